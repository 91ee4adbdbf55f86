//! `cargo xtask warp`: NNWarp's runtime on a volumetric scene (NNWarp §6).
//!
//! The scene's body runs as linear elasticity with a constant, pre-factorised system
//! (backward Euler with the scene's time step and damping, or static load increments for
//! a static scene), each node's load rotated back to its rest orientation first, and every
//! frame corrected node by node by the trained network (`weft_nn::nnwarp::NnWarpSimulation`).
//! With `--reference` the scene also runs as it is written (full nonlinear FEM), and each
//! frame's VTK carries the per-node error against it. The loop is weft-nn's
//! (`weft_nn::nnwarp::run_against_reference`); this module writes its frames.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use weft_nn::nnwarp::{NnWarpSimulation, load_model};
use weft_nn::nnwarp::{ReferenceTwins, run_against_reference};
use weft_nn::nnwarp::{WarpRunSetup, WarpRunSummary, write_frame_vtk};
use weft_sim::{AnyScene, VolumeSimulation};

use weft_data::files::write_json;

#[derive(Args)]
pub struct WarpArgs {
    /// A model directory written by `cargo xtask train nnwarp`.
    #[arg(long)]
    model: PathBuf,
    /// A volumetric scene: a built-in name (`beam-neo-hookean`, …) or a TOML file.
    #[arg(long)]
    scene: String,
    /// Output directory: `frame-NNNN.vtk` per written frame and `summary.json`.
    #[arg(long)]
    out: PathBuf,
    /// Frames to run (default: the scene's).
    #[arg(long)]
    frames: Option<usize>,
    /// Write every N-th frame's VTK (the last frame is always written).
    #[arg(long, default_value_t = 1)]
    every: usize,
    /// Also run the scene's full nonlinear FEM and write the per-node error against it.
    #[arg(long)]
    reference: bool,
    /// The built-in scene's small variant.
    #[arg(long)]
    quick: bool,
}

pub fn run(args: WarpArgs) -> anyhow::Result<()> {
    if args.every == 0 {
        bail!("--every must be at least 1");
    }
    let loaded = weft_sim::load(&args.scene, args.quick)?;
    let AnyScene::Volume(mut scene) = loaded.scene else {
        bail!(
            "{} is not a volumetric scene; NNWarp warps tetrahedral bodies",
            args.scene
        );
    };
    if let Some(f) = args.frames {
        scene.frames = f;
    }
    let base_dir = loaded.base_dir.as_deref();
    let (config, mlp) = load_model(&args.model).with_context(|| format!("loading {}", args.model.display()))?;
    let scene_material = weft_data::nnwarp::material_key(scene.material);
    if config.material != scene_material {
        // A network learns one material's nonlinearity (Luo et al. Eq. 6-7); it still
        // runs, for studies across materials, but its answer is not that material's.
        eprintln!(
            "warning: {} was trained on {}, but {} is {}: the correction is applied outside its training{}",
            args.model.display(),
            config.material,
            scene.name,
            scene_material,
            if args.reference {
                " (the error against the reference measures that)"
            } else {
                ""
            }
        );
    }
    // The reference twin builds the body, anchors and loads once; the linear twin shares them.
    let mut reference_sim = VolumeSimulation::new(scene.clone(), base_dir)?;
    let mut runtime = NnWarpSimulation::new(&reference_sim, mlp)?;
    let mesh = reference_sim.mesh().clone();
    let twins = args.reference.then(|| ReferenceTwins {
        reference: &mut reference_sim,
        others: Vec::new(),
    });
    let rest = mesh.flat_positions();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating the output directory {}", args.out.display()))?;
    let report = run_against_reference(&mut runtime, twins, scene.frames, |f| {
        if f.frame % args.every == 0 || f.frame == scene.frames {
            write_frame_vtk(&args.out, f, &rest, &mesh)?;
        }
        anyhow::Ok(())
    })
    .context("running NNWarp against the full FEM reference")?;
    let setup = WarpRunSetup {
        scene: &scene.name,
        model: &args.model,
        material: &config.material,
        reference_material: scene.material.name(),
        mesh: &mesh,
        factorization_seconds: runtime.linear().factorization_seconds(),
    };
    let summary = WarpRunSummary::new(&setup, &report, scene.frames);
    write_json(&args.out.join("summary.json"), &summary)?;
    eprintln!(
        "{}: {} frames, linear solve {:.2} ms + NNWarp {:.2} ms per frame{} → {}",
        scene.name,
        scene.frames,
        1e3 * summary.solve_seconds_per_frame,
        1e3 * summary.nnwarp_seconds_per_frame,
        summary
            .reference_seconds_per_frame
            .map_or(String::new(), |s| format!(", full FEM {:.1} ms per frame", 1e3 * s)),
        args.out.display()
    );
    Ok(())
}
