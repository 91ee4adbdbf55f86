//! `cargo xtask warp`: NNWarp's runtime on a volumetric scene (NNWarp §6).
//!
//! The scene's body runs as linear elasticity with a constant, pre-factorised system
//! (backward Euler with the scene's time step and damping, or static load increments for
//! a static scene), each node's load rotated back to its rest orientation first, and every
//! frame corrected node by node by the trained network (`weft_nn::nnwarp::NnWarpSimulation`).
//! With `--reference` the scene also runs as it is written (full nonlinear FEM), and each
//! frame's VTK carries the per-node error against it. The run is weft-nn's
//! (`weft_nn::nnwarp::WarpScene`); this module parses its flags and prints.

use std::path::PathBuf;

use clap::Args;
use weft_nn::nnwarp::{WarpScene, WarpSceneParams};

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
    let warp = WarpScene::load(WarpSceneParams {
        model: &args.model,
        scene: &args.scene,
        out: &args.out,
        frames: args.frames,
        every: args.every,
        reference: args.reference,
        quick: args.quick,
    })?;
    if let Some(warning) = warp.warning() {
        eprintln!("{warning}");
    }
    eprintln!("{}", warp.run()?.line);
    Ok(())
}
