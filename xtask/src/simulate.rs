//! `cargo xtask simulate`: run a cloth scene and write its frames.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use weft_sim::{BUILTIN_SCENES, ClothSimulation, MotionLabel, Scene};

use crate::output::{Array, write_json, write_safetensors, write_text};

#[derive(Args)]
pub struct SimulateArgs {
    /// A built-in scene name (sheet-ms, sheet-ms-holes, sheet-fem, sheet-fem-obstacle, ball-ms, ball-fem,
    /// ball-fem-soft-stretch, ball-fem-soft-bend, sheet-ms-33, sheet-ms-17) or a scene TOML file.
    pub scene: String,
    /// Number of frames to simulate (default: the scene's).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Use the scene's small variant (coarse mesh, 30 frames) — for tests and smoke runs.
    #[arg(long)]
    pub quick: bool,
    /// Output directory: frames.safetensors, scene.toml, stats.json, rest.obj.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write one OBJ per frame to OUT/obj/frame_NNNNN.obj.
    #[arg(long)]
    pub obj: bool,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
}

#[derive(Serialize)]
struct FrameStats {
    frame: usize,
    label: &'static str,
    newton_iterations: usize,
    residual_n: f64,
    seconds: f64,
    potential_energy_j: f64,
    kinetic_energy_j: f64,
}

#[derive(Serialize)]
struct Stats {
    scene: String,
    vertices: usize,
    frames: usize,
    dt_s: f64,
    total_seconds: f64,
    mean_ms_per_frame: f64,
    mean_newton_iterations: f64,
    error: Option<String>,
    per_frame: Vec<FrameStats>,
}

/// Loads a scene from a built-in name or a TOML path; returns it with the directory
/// relative file paths in it resolve against.
pub fn load_scene(name: &str, quick: bool) -> anyhow::Result<(Scene, Option<PathBuf>)> {
    if BUILTIN_SCENES.contains(&name) {
        return Ok((Scene::builtin(name, quick)?, None));
    }
    let path = Path::new(name);
    if !path.exists() {
        anyhow::bail!(
            "{name:?} is neither a built-in scene ({}) nor an existing scene file",
            BUILTIN_SCENES.join(", ")
        );
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let scene = Scene::from_toml(&text).with_context(|| format!("in {}", path.display()))?;
    Ok((scene, path.parent().map(Path::to_path_buf)))
}

pub fn run(args: SimulateArgs) -> anyhow::Result<()> {
    let (mut scene, base) = load_scene(&args.scene, args.quick)?;
    if let Some(f) = args.frames {
        scene.frames = f;
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let mut sim = ClothSimulation::new(scene.clone(), base.as_deref())?;
    let mesh = sim.mesh().clone();
    weft_mesh::io::write_obj(&args.out.join("rest.obj"), mesh.positions(), mesh.faces())?;
    write_text(&args.out.join("scene.toml"), &scene.to_toml()?)?;
    if args.obj {
        std::fs::create_dir_all(args.out.join("obj"))?;
    }

    let nv = mesh.num_vertices();
    let ng = sim.grasp_vertices().len();
    let (q0, l0) = sim.controls_at(0);
    let mut positions = mesh.flat_positions();
    let mut controls: Vec<f64> = q0.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    let mut labels = vec![l0.code()];
    let mut per_frame = Vec::new();
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(scene.frames as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:40}] {pos}/{len} frames, {per_sec}, ETA {eta}")?
            .progress_chars("=> "),
    );
    bar.set_prefix(scene.name.clone());
    let start = std::time::Instant::now();
    let mut error = None;
    for _ in 0..scene.frames {
        match sim.step() {
            Ok(frame) => {
                let m = sim.frame_index();
                per_frame.push(FrameStats {
                    frame: m,
                    label: frame.label.as_str(),
                    newton_iterations: frame.report.newton.iterations,
                    residual_n: frame.report.newton.residual,
                    seconds: frame.report.seconds,
                    potential_energy_j: frame.report.potential_energy,
                    kinetic_energy_j: frame.report.kinetic_energy,
                });
                if args.obj {
                    let p = weft_mesh::unflatten(&frame.positions);
                    weft_mesh::io::write_obj(&args.out.join(format!("obj/frame_{m:05}.obj")), &p, mesh.faces())?;
                }
                positions.extend_from_slice(&frame.positions);
                controls.extend_from_slice(&frame.controls);
                labels.push(frame.label.code());
                bar.inc(1);
            }
            Err(e) => {
                // Keep every frame simulated so far: write them, then report the failure.
                error = Some(format!("frame {}: {e}", sim.frame_index() + 1));
                break;
            }
        }
    }
    bar.finish_and_clear();
    let frames = labels.len();
    let total = start.elapsed().as_secs_f64();
    let mut meta = HashMap::new();
    meta.insert("scene".into(), scene.name.clone());
    meta.insert("dt_s".into(), scene.dt.to_string());
    meta.insert(
        "units".into(),
        "positions and controls in metres; frame 0 is the rest state".into(),
    );
    meta.insert(
        "labels".into(),
        MotionLabel::ALL
            .iter()
            .map(|l| format!("{}={}", l.code(), l.as_str()))
            .collect::<Vec<_>>()
            .join(","),
    );
    meta.insert("grasp_vertices".into(), serde_json::to_string(sim.grasp_vertices())?);
    write_safetensors(
        &args.out.join("frames.safetensors"),
        &[
            Array::f64("positions", vec![frames, nv, 3], &positions),
            Array::f64("controls", vec![frames, ng, 3], &controls),
            Array::u8("labels", &labels),
        ],
        meta,
    )?;
    let n = per_frame.len().max(1) as f64;
    let stats = Stats {
        scene: scene.name.clone(),
        vertices: nv,
        frames: per_frame.len(),
        dt_s: scene.dt,
        total_seconds: total,
        mean_ms_per_frame: 1e3 * per_frame.iter().map(|f| f.seconds).sum::<f64>() / n,
        mean_newton_iterations: per_frame.iter().map(|f| f.newton_iterations as f64).sum::<f64>() / n,
        error: error.clone(),
        per_frame,
    };
    write_json(&args.out.join("stats.json"), &stats)?;
    eprintln!(
        "{}: {} frames of {} vertices in {:.1} s ({:.1} ms/frame, {:.2} Newton iterations/frame) → {}",
        scene.name,
        stats.frames,
        nv,
        total,
        stats.mean_ms_per_frame,
        stats.mean_newton_iterations,
        args.out.display()
    );
    if let Some(e) = error {
        anyhow::bail!("simulation stopped early at {e}; the frames before it were written");
    }
    Ok(())
}
