//! Experiment `sim`: the ground-truth simulators' own speed–accuracy trade.
//!
//! - Cloth (`sheet-ms`, `ball-fem`): the scene's implicit Euler as the datasets use it
//!   (the ground truth whose time every ratio divides by), and its cheaper and dearer
//!   variants — looser and tighter Newton tolerances, inexact steps of one to three
//!   projected Newton iterations, doubled and halved time steps, coarser sheets — against a tight reference (a quarter of the time step, Newton
//!   tolerance 1e-6 of the heaviest vertex's weight).
//! - Beam (`beam`): pre-factorised linear, linear, co-rotational, StVK and Neo-Hookean
//!   FEM, all under gravity, against a tight Neo-Hookean reference (the same time step,
//!   Newton tolerance 1e-8 of the heaviest node's weight), so a material's error is its
//!   model error; a doubled step shows the time discretisation's.
//!
//! NNWarp Table 1's timings (pre-factorised linear FEM, the correction, the full frame) are
//! the `nnwarp` experiment's, all measured in its run: the report prints that table once.
//!
//! Errors are M_rms (Kavan et al., 1000 × per-coordinate RMS of raw metres: mm) and the
//! largest vertex distance (mm), over every frame each method computes, compared with the
//! reference at the same time.

use std::collections::HashMap;

use crate::error::Context;
use weft_sim::energies::{LameParameters, Material, TetElasticity};
use weft_sim::scenes::cloth::MeshSpec;
use weft_sim::scenes::volume::VolumeSolve;
use weft_sim::{ClothScene, ClothSimulation, Energy, VolumeScene, VolumeSimulation};

use super::context::EvalContext;
use crate::records::{Curve, ExperimentOutput, RmsAccumulator, Timing};
use crate::render::{View, error_png};
use weft_data::Size;
use weft_data::files::{Array, progress_bar, write_safetensors};

pub fn run(ctx: &EvalContext) -> crate::Result<ExperimentOutput> {
    let mut out = ExperimentOutput::new("sim", ctx.size);
    let quick = ctx.size == Size::Quick;
    // Simulated time per scene: enough motion to separate the methods, within the
    // standard evaluation's hour.
    cloth(ctx, &mut out, "sheet-ms", if quick { 30 } else { 60 }, true)?;
    cloth(ctx, &mut out, "ball-fem", if quick { 30 } else { 100 }, false)?;
    beam(ctx, &mut out, if quick { 20 } else { 100 })?;
    Ok(out)
}

/// One method's trajectory.
struct Run {
    method: String,
    /// Time of each stored frame (s).
    times: Vec<f64>,
    positions: Vec<Vec<f64>>,
    /// Solver seconds over the whole run.
    seconds: f64,
    /// Scene frames the run covers (simulated time / the scene's frame time).
    scene_frames: f64,
    /// Run vertex → reference vertex.
    map: Vec<usize>,
    faces: Vec<[usize; 3]>,
    /// Mean potential and kinetic energy over the frames (J).
    energies: Option<(f64, f64)>,
}

impl Run {
    fn seconds_per_frame(&self) -> f64 {
        self.seconds / self.scene_frames.max(1.0)
    }
}

/// A reference trajectory sampled every `dt` seconds.
struct Reference {
    dt: f64,
    positions: Vec<Vec<f64>>,
    seconds_per_frame: f64,
    /// Mean potential and kinetic energy (J).
    energies: Option<(f64, f64)>,
}

impl Reference {
    /// The reference frame at time `t` (an exact multiple of its step).
    fn at(&self, t: f64) -> crate::Result<&[f64]> {
        let k = (t / self.dt).round();
        crate::error::ensure!(
            (t / self.dt - k).abs() < 1e-6 && k >= 1.0,
            "time {t} s is not on the reference's grid of {} s",
            self.dt
        );
        self.positions
            .get(k as usize - 1)
            .map(Vec::as_slice)
            .context("reference shorter than the run")
    }
}

fn simulate_cloth(
    scene: &ClothScene,
    duration: f64,
    bar: &indicatif::ProgressBar,
) -> crate::Result<(ClothSimulation, Run)> {
    let steps = (duration / scene.dt).round() as usize;
    let mut s = scene.clone();
    s.frames = steps;
    let mut sim = ClothSimulation::new(s, None)?;
    let mut run = Run {
        method: String::new(),
        times: Vec::with_capacity(steps),
        positions: Vec::with_capacity(steps),
        seconds: 0.0,
        scene_frames: 0.0,
        map: Vec::new(),
        faces: sim.mesh().faces().to_vec(),
        energies: None,
    };
    let (mut pot, mut kin) = (0.0, 0.0);
    for m in 1..=steps {
        let f = sim
            .step()
            .with_context(|| format!("step {m} of {steps} (dt {} s)", scene.dt))?;
        run.seconds += f.report.seconds;
        pot += f.report.potential_energy;
        kin += f.report.kinetic_energy;
        run.times.push(m as f64 * scene.dt);
        run.positions.push(f.positions);
        bar.inc(1);
    }
    run.energies = Some((pot / steps as f64, kin / steps as f64));
    Ok((sim, run))
}

/// Maps each vertex of `coarse` to the vertex of `fine` at the same rest position.
fn nested_vertex_map(coarse: &[nalgebra::Vector3<f64>], fine: &[nalgebra::Vector3<f64>]) -> crate::Result<Vec<usize>> {
    let key = |p: &nalgebra::Vector3<f64>| [p.x, p.y, p.z].map(|c| (c * 1e9).round() as i64);
    let index: HashMap<_, _> = fine.iter().enumerate().map(|(i, p)| (key(p), i)).collect();
    coarse
        .iter()
        .map(|p| {
            index
                .get(&key(p))
                .copied()
                .context("coarse vertex not on the fine mesh")
        })
        .collect()
}

fn cloth(
    ctx: &EvalContext,
    out: &mut ExperimentOutput,
    name: &str,
    frames: usize,
    resolutions: bool,
) -> crate::Result<()> {
    let base = ClothScene::builtin(name, ctx.size == Size::Quick)?;
    let dt0 = base.dt;
    let duration = frames as f64 * dt0;
    let mut variants: Vec<(String, ClothScene)> = vec![("implicit-euler".into(), base.clone())];
    for (tag, tol) in [("1e-1", 1e-1), ("1e-2", 1e-2), ("1e-5", 1e-5)] {
        let mut s = base.clone();
        s.relative_tolerance = tol;
        variants.push((format!("newton-tol-{tag}"), s));
    }
    for (tag, f) in [("dt-2x", 2.0), ("dt-half", 0.5)] {
        let mut s = base.clone();
        s.dt = dt0 * f;
        variants.push((tag.into(), s));
    }
    // Inexact steps: one to three Newton iterations per step on per-element projected
    // Hessians, the last iterate accepted (one is Baraff & Witkin's linearised implicit
    // Euler; docs/CLOTH.md, "Inexact steps").
    for budget in [1, 2, 3] {
        let mut s = base.clone();
        s.hessian = Some(weft_sim::HessianProjection::Always);
        s.newton_budget = Some(budget);
        variants.push((format!("newton-budget-{budget}"), s));
    }
    // Chord steps: that many iterations per step with one factorisation, the later ones
    // solving with its factor (docs/CLOTH.md, "Chord steps").
    for budget in [2, 4, 6] {
        let mut s = base.clone();
        s.hessian = Some(weft_sim::HessianProjection::Always);
        s.newton_budget = Some(budget);
        s.newton_factorizations = Some(1);
        variants.push((format!("newton-chord-{budget}"), s));
    }
    if resolutions {
        if let MeshSpec::Sheet { n, size } = base.mesh {
            for (tag, div) in [("resolution-half", 2), ("resolution-quarter", 4)] {
                let mut s = base.clone();
                s.mesh = MeshSpec::Sheet {
                    n: (n - 1) / div + 1,
                    size,
                };
                variants.push((tag.into(), s));
            }
        }
    }
    let mut reference_scene = base.clone();
    reference_scene.dt = dt0 / 4.0;
    reference_scene.relative_tolerance = 1e-6;
    let total: usize = 4 * frames
        + variants
            .iter()
            .map(|(_, s)| (duration / s.dt).round() as usize)
            .sum::<usize>();
    let bar = progress_bar(ctx.quiet, total as u64, &format!("sim {name}"), "steps")?;

    let (ref_sim, ref_run) = simulate_cloth(&reference_scene, duration, &bar).context("the reference run failed")?;
    let reference = Reference {
        dt: reference_scene.dt,
        seconds_per_frame: ref_run.seconds / frames as f64,
        positions: ref_run.positions,
        energies: ref_run.energies,
    };
    let ref_mesh = ref_sim.mesh().positions().to_vec();
    out.notes.push(format!(
        "sim/{name}: {} vertices, {frames} frames of {dt0} s; reference dt {} s, Newton tolerance 1e-6 × heaviest weight, \
         {:.3} s per frame",
        ref_mesh.len(),
        reference.dt,
        reference.seconds_per_frame
    ));
    let mut runs = Vec::new();
    for (method, scene) in variants {
        match simulate_cloth(&scene, duration, &bar) {
            Ok((sim, mut run)) => {
                run.method = method;
                run.scene_frames = frames as f64;
                run.map = nested_vertex_map(sim.mesh().positions(), &ref_mesh)?;
                runs.push(run);
            }
            Err(e) => out.failures.push(format!("sim/{name}/{method}: {e:#}")),
        }
    }
    bar.finish_and_clear();
    score(ctx, out, name, &reference, runs, dt0, View::FRONT)
}

/// Scores runs against the reference: records, curves, energies, predictions, renders.
fn score(
    ctx: &EvalContext,
    out: &mut ExperimentOutput,
    scene: &str,
    reference: &Reference,
    runs: Vec<Run>,
    frame_dt: f64,
    view: View,
) -> crate::Result<()> {
    let gt = runs
        .first()
        .filter(|r| r.method == "implicit-euler" || r.method == "neo-hookean")
        .map(Run::seconds_per_frame)
        .context("the ground-truth method failed; no time ratio can be formed")?;
    let pred_dir = ctx.out.join("predictions").join("sim").join(scene);
    std::fs::create_dir_all(&pred_dir)?;
    let mut last_errors = Vec::new();
    if let Some((pot, kin)) = reference.energies {
        out.energy(scene, "reference", "potential", pot, "J");
        out.energy(scene, "reference", "kinetic", kin, "J");
    }
    for run in &runs {
        let mut acc = RmsAccumulator::default();
        let mut curve = Curve {
            scene: scene.into(),
            method: run.method.clone(),
            frames: Vec::new(),
            error_mm: Vec::new(),
            error_mm_sd: Vec::new(),
        };
        let mut truth = Vec::with_capacity(run.positions.len() * run.positions[0].len());
        for (t, x) in run.times.iter().zip(&run.positions) {
            let r = reference.at(*t)?;
            curve.frames.push(t / frame_dt);
            curve.error_mm.push(acc.add(x, r, &run.map));
            truth.extend(run.map.iter().flat_map(|&j| [r[3 * j], r[3 * j + 1], r[3 * j + 2]]));
        }
        let timing = Timing::new(run.seconds_per_frame(), gt);
        out.record(scene, &run.method, "m-rms", acc.m_rms_mm(), "mm", timing);
        out.record(scene, &run.method, "max-error", acc.max_error_mm(), "mm", timing);
        if let Some((pot, kin)) = run.energies {
            out.energy(scene, &run.method, "potential", pot, "J");
            out.energy(scene, &run.method, "kinetic", kin, "J");
        }
        out.curves.push(curve);
        let (f, v) = (run.positions.len(), run.map.len());
        let flat: Vec<f64> = run.positions.concat();
        let map: Vec<i64> = run.map.iter().map(|&j| j as i64).collect();
        let mut meta = HashMap::new();
        meta.insert(
            "units".into(),
            "positions and ground_truth [frames, vertices, 3] in metres; times [frames] in s; reference_vertex: the \
             reference mesh's vertex each vertex is compared with"
                .into(),
        );
        meta.insert("reference_dt_s".into(), reference.dt.to_string());
        write_safetensors(
            &pred_dir.join(format!("{}.safetensors", run.method)),
            &[
                Array::f64("positions", vec![f, v, 3], &flat),
                Array::f64("ground_truth", vec![f, v, 3], &truth),
                Array::f64("times", vec![f], &run.times),
                Array::i64("reference_vertex", &map),
            ],
            meta,
        )?;
        let last = run.positions.last().context("empty run")?;
        let r = reference.at(*run.times.last().unwrap_or(&0.0))?;
        let errs: Vec<f64> = run
            .map
            .iter()
            .enumerate()
            .map(|(i, &j)| {
                (0..3)
                    .map(|k| (last[3 * i + k] - r[3 * j + k]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .collect();
        last_errors.push((run, last.clone(), errs));
    }
    // One colour scale per scene, so the renders compare across methods.
    let scale = last_errors
        .iter()
        .flat_map(|(_, _, e)| e.iter().copied())
        .fold(0.0f64, f64::max)
        .max(1e-9);
    let render_dir = ctx.out.join("renders").join("sim").join(scene);
    std::fs::create_dir_all(&render_dir)?;
    for (run, x, errs) in last_errors {
        let rel = format!("renders/sim/{scene}/{}.png", run.method);
        error_png(
            &ctx.out.join(&rel),
            &x,
            &run.faces,
            &errs,
            scale,
            &format!("{scene} — {} (last frame)", run.method),
            view,
        )?;
        out.renders.push(rel);
    }
    Ok(())
}

fn simulate_volume(
    scene: &VolumeScene,
    steps: usize,
    tighten: Option<f64>,
    energy: &TetElasticity,
    masses: &[f64],
    bar: &indicatif::ProgressBar,
) -> crate::Result<(VolumeSimulation, Run)> {
    let mut s = scene.clone();
    s.frames = steps;
    let dt = match s.solve {
        VolumeSolve::ImplicitEuler { dt } | VolumeSolve::Newmark { dt, .. } | VolumeSolve::DynamicLinear { dt, .. } => {
            dt
        }
        _ => crate::error::bail!("the beam comparison needs a dynamic solve"),
    };
    let mut sim = VolumeSimulation::new(s, None)?;
    if let (Some(f), Some(settings)) = (tighten, sim.newton_settings_mut()) {
        settings.tolerance *= f;
    }
    let faces = sim.mesh().boundary_surface()?;
    let mut run = Run {
        method: String::new(),
        times: Vec::new(),
        positions: Vec::new(),
        seconds: 0.0,
        scene_frames: 0.0,
        map: (0..sim.mesh().num_vertices()).collect(),
        // Rendered on the boundary surface, indexed into the volume's nodes.
        faces: faces
            .mesh
            .faces()
            .iter()
            .map(|f| f.map(|v| faces.volume_vertex[v]))
            .collect(),
        energies: None,
    };
    let (mut pot, mut kin) = (0.0, 0.0);
    let mut prev = sim.mesh().flat_positions();
    for m in 1..=steps {
        let f = sim.step().with_context(|| format!("step {m} of {steps} (dt {dt} s)"))?;
        run.seconds += f.seconds;
        // Every method's frames are scored with the reference's energy (Neo-Hookean).
        pot += energy.value(&f.positions);
        kin += 0.5
            * masses
                .iter()
                .enumerate()
                .map(|(v, m)| {
                    m * (0..3)
                        .map(|k| ((f.positions[3 * v + k] - prev[3 * v + k]) / dt).powi(2))
                        .sum::<f64>()
                })
                .sum::<f64>();
        prev.clone_from(&f.positions);
        run.times.push(m as f64 * dt);
        run.positions.push(f.positions);
        bar.inc(1);
    }
    run.energies = Some((pot / steps as f64, kin / steps as f64));
    Ok((sim, run))
}

fn beam(ctx: &EvalContext, out: &mut ExperimentOutput, frames: usize) -> crate::Result<()> {
    let base = VolumeScene::builtin("beam-neo-hookean", ctx.size == Size::Quick)?;
    let VolumeSolve::ImplicitEuler { dt: dt0 } = base.solve else {
        crate::error::bail!("beam-neo-hookean is expected to use implicit Euler");
    };
    let mesh = base.build_mesh(None)?;
    let lame = LameParameters::from_young_poisson(base.young, base.poisson)?;
    let energy = TetElasticity::new(&mesh, Material::NeoHookean, lame)?;
    let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), base.density);
    let with = |material: Material, solve: VolumeSolve| VolumeScene {
        material,
        solve,
        ..base.clone()
    };
    let euler = |dt| VolumeSolve::ImplicitEuler { dt };
    // (method, scene, Newton tolerance factor)
    let variants: Vec<(&str, VolumeScene, Option<f64>)> = vec![
        ("neo-hookean", base.clone(), None),
        ("neo-hookean-newton-tol-1e-2", base.clone(), Some(1e3)),
        ("neo-hookean-dt-2x", with(Material::NeoHookean, euler(2.0 * dt0)), None),
        ("stvk", with(Material::StVK, euler(dt0)), None),
        ("corotational", with(Material::CoRotational, euler(dt0)), None),
        ("linear", with(Material::Linear, euler(dt0)), None),
        (
            "prefactorized-linear",
            with(
                Material::Linear,
                VolumeSolve::DynamicLinear {
                    dt: dt0,
                    rayleigh_mass: 0.0,
                    rayleigh_stiffness: 0.0,
                },
            ),
            None,
        ),
    ];
    let duration = frames as f64 * dt0;
    let steps_of = |s: &VolumeScene| match s.solve {
        VolumeSolve::ImplicitEuler { dt } | VolumeSolve::DynamicLinear { dt, .. } => (duration / dt).round() as usize,
        _ => frames,
    };
    let total = frames + variants.iter().map(|(_, s, _)| steps_of(s)).sum::<usize>();
    let bar = progress_bar(ctx.quiet, total as u64, "sim beam", "steps")?;
    // The reference keeps the ground truth's time step so that the materials' errors are
    // their model error alone (the doubled step shows the time discretisation's).
    let (_, ref_run) =
        simulate_volume(&base, frames, Some(1e-3), &energy, &masses, &bar).context("the beam reference run failed")?;
    let reference = Reference {
        dt: dt0,
        seconds_per_frame: ref_run.seconds / frames as f64,
        positions: ref_run.positions,
        energies: ref_run.energies,
    };
    out.notes.push(format!(
        "sim/beam: {} nodes, {} tets, E = {} Pa, ν = {}, gravity, {frames} frames of {dt0} s; reference Neo-Hookean dt {} \
         s (the ground truth's), Newton tolerance 1e-8 × heaviest weight, {:.3} s per frame",
        mesh.num_vertices(),
        mesh.num_tets(),
        base.young,
        base.poisson,
        reference.dt,
        reference.seconds_per_frame
    ));
    let mut runs = Vec::new();
    for (method, scene, tighten) in variants {
        match simulate_volume(&scene, steps_of(&scene), tighten, &energy, &masses, &bar) {
            Ok((_, mut run)) => {
                run.method = method.into();
                run.scene_frames = frames as f64;
                runs.push(run);
            }
            Err(e) => out.failures.push(format!("sim/beam/{method}: {e:#}")),
        }
    }
    bar.finish_and_clear();
    score(ctx, out, "beam", &reference, runs, dt0, View::BEAM)
}
