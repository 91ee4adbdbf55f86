//! `cargo xtask simulate`: run a cloth, volumetric or soft-tissue scene and write its frames.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use weft_sim::{
    BUILTIN_SCENES, BUILTIN_VOLUME_SCENES, ClothSimulation, MotionLabel, Scene, SoftTissueScene, VolumeScene,
    VolumeSimulation,
};

use crate::output::{Array, write_json, write_safetensors, write_text};

#[derive(Args)]
pub struct SimulateArgs {
    /// A built-in scene name — cloth: sheet-ms, sheet-ms-holes, sheet-fem, sheet-fem-obstacle, ball-ms,
    /// ball-fem, ball-fem-soft-stretch, ball-fem-soft-bend, sheet-ms-33, sheet-ms-17; volume: beam-linear,
    /// beam-corotational, beam-stvk, beam-neo-hookean, beam-neo-hookean-field, beam-static-linear; soft
    /// tissue: limb — or a scene TOML file (`type = "volume"` or `type = "soft-tissue"`; no type key: cloth).
    pub scene: String,
    /// Number of frames to simulate (default: the scene's).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Use the scene's small variant (coarse mesh, few frames) — for tests and smoke runs.
    #[arg(long)]
    pub quick: bool,
    /// Output directory: frames.safetensors, scene.toml, stats.json, and the rest mesh (rest.obj; volume scenes
    /// also rest.node/.ele, rest_surface.obj and final.vtk with the displacement field).
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
}

/// The three kinds of scene `simulate` runs.
pub enum AnyScene {
    Cloth(Scene),
    Volume(VolumeScene),
    SoftTissue(SoftTissueScene),
}

/// Loads a scene of any kind from a built-in name or a TOML file (dispatching on its `type` key).
pub fn load_any_scene(name: &str, quick: bool) -> anyhow::Result<(AnyScene, Option<PathBuf>)> {
    if BUILTIN_VOLUME_SCENES.contains(&name) {
        return Ok((AnyScene::Volume(VolumeScene::builtin(name, quick)?), None));
    }
    if name == "limb" {
        return Ok((AnyScene::SoftTissue(SoftTissueScene::builtin(quick)), None));
    }
    let path = Path::new(name);
    if !BUILTIN_SCENES.contains(&name) && path.exists() {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let value: toml::Table = text
            .parse()
            .with_context(|| format!("{} is not valid TOML", path.display()))?;
        let base = path.parent().map(Path::to_path_buf);
        let scene = match value.get("type").and_then(|t| t.as_str()) {
            Some("volume") => {
                AnyScene::Volume(VolumeScene::from_toml(&text).with_context(|| format!("in {}", path.display()))?)
            }
            Some("soft-tissue") => AnyScene::SoftTissue(
                SoftTissueScene::from_toml(&text).with_context(|| format!("in {}", path.display()))?,
            ),
            Some(other) => anyhow::bail!(
                "{}: unknown scene type {other:?} (volume, soft-tissue, or none for cloth)",
                path.display()
            ),
            None => AnyScene::Cloth(Scene::from_toml(&text).with_context(|| format!("in {}", path.display()))?),
        };
        return Ok((scene, base));
    }
    let (scene, base) = load_scene(name, quick)?;
    Ok((AnyScene::Cloth(scene), base))
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
    let (scene, base) = load_any_scene(&args.scene, args.quick)?;
    if args.vertices.is_some() && !matches!(scene, AnyScene::SoftTissue(_)) {
        anyhow::bail!("--vertices applies to the limb scene only");
    }
    match scene {
        AnyScene::Cloth(s) => run_cloth(s, base, &args),
        AnyScene::Volume(s) => run_volume(s, base, &args),
        AnyScene::SoftTissue(s) => run_soft_tissue(s, &args),
    }
}

fn progress_bar(args: &SimulateArgs, frames: usize, name: &str) -> anyhow::Result<ProgressBar> {
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(frames as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:40}] {pos}/{len} frames, {per_sec}, ETA {eta}")?
            .progress_chars("=> "),
    );
    bar.set_prefix(name.to_string());
    Ok(bar)
}

#[derive(Serialize)]
struct SolveFrameStats {
    frame: usize,
    newton_iterations: usize,
    residual_n: f64,
    seconds: f64,
}

#[derive(Serialize)]
struct SolveStats {
    scene: String,
    vertices: usize,
    frames: usize,
    total_seconds: f64,
    mean_ms_per_frame: f64,
    mean_newton_iterations: f64,
    error: Option<String>,
    per_frame: Vec<SolveFrameStats>,
}

impl SolveStats {
    fn new(scene: &str, vertices: usize, per_frame: Vec<SolveFrameStats>, total: f64, error: Option<String>) -> Self {
        let n = per_frame.len().max(1) as f64;
        Self {
            scene: scene.into(),
            vertices,
            frames: per_frame.len(),
            total_seconds: total,
            mean_ms_per_frame: 1e3 * per_frame.iter().map(|f| f.seconds).sum::<f64>() / n,
            mean_newton_iterations: per_frame.iter().map(|f| f.newton_iterations as f64).sum::<f64>() / n,
            error,
            per_frame,
        }
    }
}

fn run_volume(mut scene: VolumeScene, base: Option<PathBuf>, args: &SimulateArgs) -> anyhow::Result<()> {
    if let Some(f) = args.frames {
        scene.frames = f;
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let mut sim = VolumeSimulation::new(scene.clone(), base.as_deref())?;
    let mesh = sim.mesh().clone();
    let surface = mesh.boundary_surface()?;
    weft_mesh::io::write_tetgen(&args.out.join("rest.node"), &mesh)?;
    weft_mesh::io::write_obj(
        &args.out.join("rest_surface.obj"),
        surface.mesh.positions(),
        surface.mesh.faces(),
    )?;
    write_text(&args.out.join("scene.toml"), &scene.to_toml()?)?;
    if args.obj {
        std::fs::create_dir_all(args.out.join("obj"))?;
    }
    let rest = mesh.flat_positions();
    let nv = mesh.num_vertices();
    let mut positions = rest.clone();
    let mut per_frame = Vec::new();
    let bar = progress_bar(args, scene.frames, &scene.name)?;
    let start = std::time::Instant::now();
    let mut error = None;
    for _ in 0..scene.frames {
        match sim.step() {
            Ok(f) => {
                let m = sim.frame_index();
                per_frame.push(SolveFrameStats {
                    frame: m,
                    newton_iterations: f.iterations,
                    residual_n: f.residual,
                    seconds: f.seconds,
                });
                if args.obj {
                    let p: Vec<_> = surface
                        .volume_vertex
                        .iter()
                        .map(|&v| {
                            nalgebra::Vector3::new(f.positions[3 * v], f.positions[3 * v + 1], f.positions[3 * v + 2])
                        })
                        .collect();
                    weft_mesh::io::write_obj(
                        &args.out.join(format!("obj/frame_{m:05}.obj")),
                        &p,
                        surface.mesh.faces(),
                    )?;
                }
                positions.extend_from_slice(&f.positions);
                bar.inc(1);
            }
            Err(e) => {
                error = Some(format!("frame {}: {e}", sim.frame_index() + 1));
                break;
            }
        }
    }
    bar.finish_and_clear();
    let frames = positions.len() / (3 * nv);
    let displacements: Vec<f64> = positions
        .iter()
        .enumerate()
        .map(|(i, p)| p - rest[i % rest.len()])
        .collect();
    let last = &displacements[displacements.len() - 3 * nv..];
    let last_positions = weft_mesh::unflatten(&positions[positions.len() - 3 * nv..]);
    weft_mesh::io::write_vtk_tets(
        &args.out.join("final.vtk"),
        &last_positions,
        mesh.tets(),
        &[("displacement", 3, last)],
    )?;
    let mut meta = HashMap::new();
    meta.insert("scene".into(), scene.name.clone());
    meta.insert(
        "units".into(),
        "positions and displacements in metres; frame 0 is the rest state".into(),
    );
    meta.insert("anchors".into(), serde_json::to_string(sim.anchors())?);
    write_safetensors(
        &args.out.join("frames.safetensors"),
        &[
            Array::f64("positions", vec![frames, nv, 3], &positions),
            Array::f64("displacements", vec![frames, nv, 3], &displacements),
        ],
        meta,
    )?;
    let stats = SolveStats::new(&scene.name, nv, per_frame, start.elapsed().as_secs_f64(), error);
    finish(args, &stats, &format!("{nv} nodes / {} tets", mesh.num_tets()))
}

/// Writes `stats.json`, reports, and turns an early stop into an error (after the frames
/// before it were written).
fn finish(args: &SimulateArgs, stats: &SolveStats, what: &str) -> anyhow::Result<()> {
    write_json(&args.out.join("stats.json"), stats)?;
    eprintln!(
        "{}: {} frames of {what} in {:.1} s ({:.1} ms/frame, {:.2} Newton iterations/frame) → {}",
        stats.scene,
        stats.frames,
        stats.total_seconds,
        stats.mean_ms_per_frame,
        stats.mean_newton_iterations,
        args.out.display()
    );
    if let Some(e) = &stats.error {
        anyhow::bail!("simulation stopped early at {e}; the frames before it were written");
    }
    Ok(())
}

fn run_soft_tissue(mut scene: SoftTissueScene, args: &SimulateArgs) -> anyhow::Result<()> {
    if let Some(f) = args.frames {
        scene.frames = f;
    }
    match args.vertices {
        None => {}
        Some(6890) => scene.resolution = weft_sim::volume_scene::LimbResolution::Smpl,
        Some(1410) => scene.resolution = weft_sim::volume_scene::LimbResolution::Default,
        Some(v) => {
            anyhow::bail!("--vertices {v}: the limb comes in 1410 (default) and 6890 (SMPL-size) surface vertices")
        }
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let mut sim = scene.build()?;
    let surface = sim.surface().mesh.clone();
    weft_mesh::io::write_obj(&args.out.join("rest.obj"), surface.positions(), surface.faces())?;
    write_text(&args.out.join("scene.toml"), &scene.to_toml()?)?;
    let nv = surface.num_vertices();
    let mut skinned = sim.skinned_surface();
    let mut simulated = sim.simulated_surface();
    let mut per_frame = Vec::new();
    let bar = progress_bar(args, scene.frames, &scene.name)?;
    let start = std::time::Instant::now();
    let mut error = None;
    for _ in 0..scene.frames {
        match sim.step_frame() {
            Ok(r) => {
                per_frame.push(SolveFrameStats {
                    frame: per_frame.len() + 1,
                    newton_iterations: r.steps.iter().map(|s| s.newton.iterations).sum(),
                    residual_n: r.steps.last().map_or(0.0, |s| s.newton.residual),
                    seconds: r.seconds,
                });
                let y = sim.simulated_surface();
                if args.obj {
                    let m = per_frame.len();
                    std::fs::create_dir_all(args.out.join("obj"))?;
                    let p = weft_mesh::unflatten(&y);
                    weft_mesh::io::write_obj(&args.out.join(format!("obj/frame_{m:05}.obj")), &p, surface.faces())?;
                }
                skinned.extend(sim.skinned_surface());
                simulated.extend(y);
                bar.inc(1);
            }
            Err(e) => {
                error = Some(format!("frame {}: {e}", per_frame.len() + 1));
                break;
            }
        }
    }
    bar.finish_and_clear();
    let frames = simulated.len() / (3 * nv);
    let mut meta = HashMap::new();
    meta.insert("scene".into(), scene.name.clone());
    meta.insert(
        "units".into(),
        "metres; skinned = X_t (kinematics only), simulated = positions = Y_t (Neo-Hookean), same vertex order as rest.obj".into(),
    );
    meta.insert("frame_dt_s".into(), scene.params.frame_dt.to_string());
    write_safetensors(
        &args.out.join("frames.safetensors"),
        &[
            Array::f64("positions", vec![frames, nv, 3], &simulated),
            Array::f64("skinned", vec![frames, nv, 3], &skinned),
            Array::f64("simulated", vec![frames, nv, 3], &simulated),
        ],
        meta,
    )?;
    let stats = SolveStats::new(&scene.name, nv, per_frame, start.elapsed().as_secs_f64(), error);
    finish(args, &stats, &format!("{nv} surface vertices"))
}

fn run_cloth(mut scene: Scene, base: Option<PathBuf>, args: &SimulateArgs) -> anyhow::Result<()> {
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
