//! `cargo xtask simulate`: run a cloth, volumetric or soft-tissue scene and write its frames.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use serde::Serialize;
use weft_sim::AnyScene;
use weft_sim::scenes::volume::LimbResolution;

use weft_data::files::{progress_bar, write_json, write_safetensors, write_text};
use weft_data::record::{FrameStats, Recorder, Recording};

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
}

#[derive(Serialize)]
struct Stats<'a> {
    scene: &'a str,
    vertices: usize,
    frames: usize,
    total_seconds: f64,
    mean_ms_per_frame: f64,
    mean_newton_iterations: f64,
    error: Option<&'a str>,
    per_frame: &'a [FrameStats],
}

pub fn run(args: SimulateArgs) -> anyhow::Result<()> {
    let mut loaded = weft_sim::load(&args.scene, args.quick)?;
    if let Some(f) = args.frames {
        loaded.scene.set_frames(f);
    }
    match (&mut loaded.scene, args.vertices) {
        (_, None) => {}
        (AnyScene::SoftTissue(s), Some(6890)) => s.resolution = LimbResolution::Smpl,
        (AnyScene::SoftTissue(s), Some(1410)) => s.resolution = LimbResolution::Default,
        (AnyScene::SoftTissue(_), Some(v)) => {
            anyhow::bail!("--vertices {v}: the limb comes in 1410 (default) and 6890 (SMPL-size) surface vertices")
        }
        _ => anyhow::bail!("--vertices applies to the limb scene only"),
    }
    match (&mut loaded.scene, args.globalization.as_deref()) {
        (_, None) => {}
        (AnyScene::Cloth(c), Some(g)) => {
            c.globalization = Some(serde_json::from_value(serde_json::Value::String(g.into()))?);
        }
        _ => anyhow::bail!("--globalization applies to cloth scenes only"),
    }
    match (
        &mut loaded.scene,
        args.hessian.as_deref(),
        args.newton_budget,
        args.newton_factorizations,
    ) {
        (_, None, None, None) => {}
        (AnyScene::Cloth(c), hessian, budget, factorizations) => {
            anyhow::ensure!(
                budget != Some(0),
                "--newton-budget must be at least 1 (omit it to solve every step to the tolerance)"
            );
            anyhow::ensure!(
                factorizations != Some(0),
                "--newton-factorizations must be at least 1 (omit it to factorise at every iteration)"
            );
            if let Some(h) = hessian {
                c.hessian = Some(serde_json::from_value(serde_json::Value::String(h.into()))?);
            }
            if budget.is_some() {
                c.newton_budget = budget;
            }
            if factorizations.is_some() {
                c.newton_factorizations = factorizations;
            }
            c.validate()?;
        }
        _ => anyhow::bail!("--hessian, --newton-budget and --newton-factorizations apply to cloth scenes only"),
    }
    let out = &args.out;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut recorder = Recorder::new(&loaded)?;
    let name = loaded.scene.name().to_string();
    write_text(&out.join("scene.toml"), &loaded.scene.to_toml()?)?;

    // The surface written per frame with --obj, as (faces, surface vertex → recorded vertex).
    let (faces, surface_vertex, what) = match &recorder {
        Recorder::Cloth(s) => {
            let m = s.mesh();
            weft_mesh::io::write_obj(&out.join("rest.obj"), m.positions(), m.faces())?;
            let n = m.num_vertices();
            (m.faces().to_vec(), (0..n).collect::<Vec<_>>(), format!("{n} vertices"))
        }
        Recorder::Volume(s) => {
            let mesh = s.mesh();
            let surface = mesh.boundary_surface()?;
            weft_mesh::io::write_tetgen(&out.join("rest.node"), mesh)?;
            weft_mesh::io::write_obj(
                &out.join("rest_surface.obj"),
                surface.mesh.positions(),
                surface.mesh.faces(),
            )?;
            let what = format!("{} nodes / {} tets", mesh.num_vertices(), mesh.num_tets());
            (surface.mesh.faces().to_vec(), surface.volume_vertex, what)
        }
        Recorder::SoftTissue(s) => {
            let m = &s.surface().mesh;
            weft_mesh::io::write_obj(&out.join("rest.obj"), m.positions(), m.faces())?;
            let n = m.num_vertices();
            (m.faces().to_vec(), (0..n).collect(), format!("{n} surface vertices"))
        }
    };
    if args.obj {
        std::fs::create_dir_all(out.join("obj"))?;
    }
    let bar = progress_bar(args.quiet, loaded.scene.frames() as u64, &name, "frames")?;
    let rec = recorder.record(&name, loaded.scene.frames(), &bar, |m, r| {
        if args.obj {
            let x = r.positions();
            let p: Vec<_> = surface_vertex
                .iter()
                .map(|&v| nalgebra::Vector3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2]))
                .collect();
            weft_mesh::io::write_obj(&out.join(format!("obj/frame_{m:05}.obj")), &p, &faces)?;
        }
        Ok(())
    })?;
    bar.finish_and_clear();
    if let Recorder::Volume(s) = &recorder {
        // The last frame with its displacement field, for ParaView.
        let x = s.positions();
        let rest = s.mesh().flat_positions();
        let u: Vec<f64> = x.iter().zip(&rest).map(|(a, b)| a - b).collect();
        weft_mesh::io::write_vtk_tets(
            &out.join("final.vtk"),
            &weft_mesh::unflatten(&x),
            s.mesh().tets(),
            &[("displacement", 3, &u)],
        )?;
    }
    write_safetensors(&out.join("frames.safetensors"), &rec.to_arrays(), rec.metadata.clone())?;
    finish(out, &rec, &what)
}

/// Writes `stats.json`, reports, and turns an early stop into an error (after the frames
/// before it were written).
fn finish(out: &std::path::Path, rec: &Recording, what: &str) -> anyhow::Result<()> {
    let stats = Stats {
        scene: &rec.scene,
        vertices: rec.vertices,
        frames: rec.per_frame.len(),
        total_seconds: rec.total_seconds,
        mean_ms_per_frame: 1e3 * rec.seconds_per_frame(),
        mean_newton_iterations: rec.mean_newton_iterations(),
        error: rec.error.as_deref(),
        per_frame: &rec.per_frame,
    };
    write_json(&out.join("stats.json"), &stats)?;
    eprintln!(
        "{}: {} frames of {what} in {:.1} s ({:.1} ms/frame, {:.2} Newton iterations/frame) → {}",
        rec.scene,
        stats.frames,
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
