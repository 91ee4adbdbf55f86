//! `cargo xtask simulate`: run a cloth, volumetric or soft-tissue scene and write its frames.

use std::path::PathBuf;

use clap::Args;
use weft_data::simulate::{SceneOverrides, SimulateStats, simulate_into};

#[derive(Args)]
pub struct SimulateArgs {
    /// A built-in scene name — cloth: sheet-ms, sheet-ms-holes, sheet-fem, sheet-fem-obstacle, ball-ms,
    /// ball-fem, ball-fem-soft-stretch, ball-fem-soft-bend, sheet-ms-33, sheet-ms-17; volume: beam-linear,
    /// beam-corotational, beam-stvk, beam-neo-hookean, beam-neo-hookean-field, beam-static-linear; soft
    /// tissue: limb, limb-jiggle — or a scene TOML file (`type = "volume"` or `type = "soft-tissue"`; no type
    /// key: cloth).
    pub scene: String,
    /// Number of frames to simulate (default: the scene's).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Use the scene's small variant (coarse mesh, few frames) — for tests and smoke runs.
    #[arg(long)]
    pub quick: bool,
    /// Output directory: frames.safetensors, scene.toml, stats.json and the rest shape: rest.obj for cloth and
    /// soft tissue (its surface); for volume scenes rest.node/.ele, rest_surface.obj and final.vtk with the
    /// displacement field.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write one OBJ per frame (the surface) to OUT/obj/frame_NNNNN.obj.
    #[arg(long)]
    pub obj: bool,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Limb scene only: surface resolution by vertex count (6890 = the SMPL body's count, for speed
    /// measurements; 1410 = the default).
    #[arg(long)]
    pub vertices: Option<usize>,
    /// Cloth scenes only: Newton's globalisation, overriding the scene's.
    #[arg(long, value_parser = ["line-search", "trust-region"])]
    pub globalization: Option<String>,
    /// Cloth scenes only: how Newton makes the Hessian positive definite, overriding the scene's
    #[arg(long, value_parser = ["always", "when-indefinite", "never"])]
    pub hessian: Option<String>,
    /// Cloth scenes only: inexact steps, at most this many Newton iterations per time step, the
    /// last iterate accepted (with `--hessian always`, one per step is Baraff & Witkin's
    /// linearised implicit Euler); docs/CLOTH.md, "Inexact steps"
    #[arg(long)]
    pub newton_budget: Option<usize>,
    /// Cloth scenes only: at most this many numeric factorisations per time step; later
    /// iterations reuse the last factor (chord steps; with `--newton-budget`, inexact steps of
    /// one factorisation and a few solves); docs/CLOTH.md, "Inexact steps"
    #[arg(long)]
    pub newton_factorizations: Option<usize>,
    /// Cloth scenes only: a surrogate model directory (`cargo xtask train
    /// inertial-correction` or `inertial-correction-mlp`) proposing every frame under the guard (docs/GUARD.md); writes
    /// `guard.json` with each frame's outcome, estimate, Newton iterations and times.
    #[arg(long)]
    pub surrogate: Option<PathBuf>,
    /// With --surrogate: the guard's tolerance, in mm (mass-weighted RMS per coordinate)
    /// or `truth` for the ground truth's own convergence test [default: truth].
    #[arg(long, requires = "surrogate")]
    pub tolerance: Option<String>,
    /// With --surrogate and a tolerance in mm: accept a proposal only on the certified bound
    /// (a guarantee, where the step's convexity is certified) instead of the Newton-step
    /// estimate.
    #[arg(long, requires = "surrogate")]
    pub certified: bool,
}

pub fn run(args: SimulateArgs) -> anyhow::Result<()> {
    let mut loaded = weft_sim::load(&args.scene, args.quick)?;
    if let Some(f) = args.frames {
        loaded.scene.set_frames(f);
    }
    let overrides = SceneOverrides {
        vertices: args.vertices,
        globalization: args.globalization,
        hessian: args.hessian,
        newton_budget: args.newton_budget,
        newton_factorizations: args.newton_factorizations,
    };
    overrides.apply(&mut loaded.scene)?;
    let out = &args.out;
    if let Some(dir) = &args.surrogate {
        let settings = weft_data::simulate::guard_settings(args.tolerance.as_deref(), args.certified)?;
        let surrogate = weft_nn::inertial_correction_mlp::load_surrogate(dir)?;
        let run = weft_data::simulate::simulate_guarded_into(&loaded, surrogate, settings, out, args.quiet)?;
        let t = &run.totals;
        eprintln!(
            "{} under the guard ({}): {} frames in {:.1} s ({:.1} ms/frame); {} accepted, {} corrected, {} rejected; \
             {} Newton iterations → {}",
            run.scene,
            run.surrogate,
            t.frames,
            run.total_seconds,
            1e3 * run.total_seconds / t.frames.max(1) as f64,
            t.accepted,
            t.corrected,
            t.rejected,
            t.newton_iterations,
            out.display()
        );
        return Ok(());
    }
    let run = simulate_into(&loaded, out, args.obj, args.quiet)?;
    let (rec, stats) = (&run.recording, SimulateStats::new(&run.recording));
    eprintln!(
        "{}: {} frames of {} in {:.1} s ({:.1} ms/frame, {:.2} Newton iterations/frame) → {}",
        rec.scene,
        stats.frames,
        run.what,
        rec.total_seconds,
        stats.mean_ms_per_frame,
        stats.mean_newton_iterations,
        out.display()
    );
    if let Some(e) = &rec.error {
        anyhow::bail!("simulation stopped early at {e}; the frames before it were written");
    }
    Ok(())
}
