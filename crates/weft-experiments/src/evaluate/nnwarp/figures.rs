//! The nnwarp experiment's figures and timings: NNWarp Table 1 measured on this machine,
//! the error as the load and the field's direction leave the trained range (Figs. 18–19),
//! and the beam tip's trajectory under a suddenly applied field (Fig. 15).

use std::path::Path;
use std::time::Instant;

use nalgebra::Vector3;
use weft_nn::nnwarp::{NnWarp, NnWarpSimulation, ReferenceTwins, WarpContext, load_model, run_against_reference};
use weft_sim::energies::{LameParameters, Material, TetElasticity};
use weft_sim::scenes::volume::LimbResolution;
use weft_sim::warp::FieldDirection;
use weft_sim::{LinearSolve, PrefactorizedLinear};

use super::data::{Shape, limb};
use super::scoring::{Bench, METHODS, Reference, Scored, field_tag};
use super::{DENSITY, FIELD_ANGLES, POISSON, WarpMaterial, YOUNG};
use crate::error::Context;
use crate::records::{ExperimentOutput, LinePlot, Series, Timing};
use weft_data::Size;

/// NNWarp Table 1, all measured here: the training beam and the ~50 k-tet limb (quick:
/// the quick limb), with the Neo-Hookean network `model`. The report's one NNWarp Table 1:
/// every column is a record of this experiment, measured in one run, so the figures that
/// divide one by another (FPS, the ratio to the full frame) come from the same run.
pub(super) fn timing_table(
    out: &mut ExperimentOutput,
    size: Size,
    shapes: &[Shape],
    model: &Path,
    lame: LameParameters,
) -> crate::Result<()> {
    let mut timing_rows = Vec::new();
    // NNWarp Table 1's bodies: the training beam and the ~50 k-tet limb (quick: the
    // quick limb), against the paper's beam and dragon.
    let timed_limb = limb(if size == Size::Quick {
        LimbResolution::Quick
    } else {
        LimbResolution::Benchmark
    })?;
    for shape in shapes.iter().filter(|s| s.name == "beam").chain([&timed_limb]) {
        let paper = if shape.name == "beam" { PAPER_BEAM } else { PAPER_DRAGON };
        timing_rows.push(timing_row(out, shape, model, lame, &paper)?);
    }
    out.tables.push(crate::paper::Table {
        title: "NNWarp (Luo et al.) Table 1 — time performance, paper / ours".into(),
        caption: "All of ours measured in this run on this machine, on the network's material (E = 100 kPa, \
                  ν = 0.3, gravity, the body clamped as in this experiment): pre-factorised linear FEM \
                  (ordering, symbolic and numeric Cholesky of the system matrix; one static solve), the \
                  Neo-Hookean network's node-wise correction, frames per second of solve and correction together, \
                  and, ours only, one full Neo-Hookean implicit-Euler frame (Δt = 0.01 s) on the same body. The \
                  paper: Eigen SimplicialLLT on an 8-core i7 at 3.0 GHz; its beam against our beam, its dragon (the \
                  FPS column: its ~52 k-tet bodies together) against our limb."
            .into(),
        header: [
            "body (paper / ours)",
            "tetrahedra",
            "factorisation",
            "solve",
            "NNWarp correction",
            "FPS",
            "full Neo-Hookean frame (ours)",
        ]
        .map(String::from)
        .to_vec(),
        rows: timing_rows,
    });
    Ok(())
}

/// NNWarp Table 1's figures for one of its bodies: the cells as printed (tetrahedra,
/// factorisation, solve, FPS) and the values the records carry as `paper_value` (`None`
/// where the paper prints a bound or a range).
struct PaperTiming {
    model: &'static str,
    printed: [&'static str; 4],
    tetrahedra: f64,
    factorization: f64,
    solve: Option<f64>,
    fps: Option<f64>,
}

/// NNWarp Table 1's beam: 2,629 tets, 6.9 ms, "< 1 ms", 333 FPS.
const PAPER_BEAM: PaperTiming = PaperTiming {
    model: "Beam",
    printed: ["2,629", "6.9 ms", "< 1 ms", "333"],
    tetrahedra: 2629.0,
    factorization: 0.0069,
    solve: None,
    fps: Some(333.0),
};

/// NNWarp Table 1's dragon, the ~50 k-tet body nearest the limb: 51,850 tets, 307 ms,
/// 15 ms (the paper's 15–18 FPS is for its ~52 k-tet bodies together).
const PAPER_DRAGON: PaperTiming = PaperTiming {
    model: "Dragon",
    printed: ["51,850", "307 ms", "15 ms", "15–18"],
    tetrahedra: 51850.0,
    factorization: 0.307,
    solve: Some(0.015),
    fps: None,
};

/// One empty line per method, in [`METHODS`] order.
fn method_series() -> Vec<Series> {
    METHODS
        .iter()
        .map(|m| Series {
            label: m.to_string(),
            x: Vec::new(),
            y: Vec::new(),
        })
        .collect()
}

/// Adds every method's error at `x`.
fn push_point(series: &mut [Series], x: f64, scored: &Scored) {
    for (s, e) in series.iter_mut().zip(scored.errors) {
        s.x.push(x);
        s.y.push(e);
    }
}

/// NNWarp Fig. 18: `rel-error` of every method as the load grows past the trained range
/// (which ends where the linear answer moves a node by 2), Neo-Hookean.
pub(super) fn load_extrapolation(
    root: &Path,
    model: &Path,
    shape: &Shape,
    direction: Vector3<f64>,
    field: FieldDirection,
    lame: LameParameters,
    size: Size,
) -> crate::Result<LinePlot> {
    let mut bench = Bench::new(shape, direction, lame)?;
    let nnwarp = [bench.nnwarp(model, field)?];
    let mut reference = Reference::new(root, &bench, WarpMaterial::NeoHookean, lame, &field_tag(FIELD_ANGLES.0))?;
    let levels: Vec<f64> = if size == Size::Quick {
        vec![0.5, 1.5, 2.5]
    } else {
        (1..=12).map(|k| 0.25 * k as f64).collect()
    };
    let mut series = method_series();
    for level in levels {
        // Past the reach of the nonlinear reference the curve ends.
        let Ok(scored) = bench.score(&nnwarp, &mut reference, level) else {
            break;
        };
        push_point(&mut series, level, &scored);
    }
    crate::error::ensure!(!series[0].x.is_empty(), "no load could be scored");
    Ok(LinePlot {
        name: format!("extrapolation-load-{}", shape.name),
        title: format!(
            "nnwarp / {}/neo-hookean: error as the load leaves the trained range (ends at 2)",
            shape.name
        ),
        x_label: "largest linear node displacement (unit-sphere units)".into(),
        y_label: "rel-error".into(),
        log_y: true,
        series,
    })
}

/// NNWarp Fig. 19: `rel-error` as the field's azimuth α leaves the trained quarter
/// hemisphere (α ∈ [0, π/2]; β fixed), at the middle load, Neo-Hookean. Each direction is
/// a fresh body: its contextual features and its reference depend on the field.
pub(super) fn direction_extrapolation(
    root: &Path,
    model: &Path,
    shape: &Shape,
    lame: LameParameters,
    size: Size,
) -> crate::Result<LinePlot> {
    let alphas: Vec<f64> = if size == Size::Quick {
        vec![0.4, 1.2, 2.4]
    } else {
        (0..8).map(|k| 0.4 * k as f64).collect()
    };
    let mut series = method_series();
    for alpha in alphas {
        let direction = Vector3::from(weft_sim::energies::hemisphere_direction(alpha, FIELD_ANGLES.1));
        let mut bench = Bench::new(shape, direction, lame)?;
        let nnwarp = [bench.nnwarp(model, FieldDirection::Directional(direction))?];
        let mut reference = Reference::new(root, &bench, WarpMaterial::NeoHookean, lame, &field_tag(alpha))?;
        let Ok(scored) = bench.score(&nnwarp, &mut reference, 1.0) else {
            continue;
        };
        push_point(&mut series, alpha, &scored);
    }
    crate::error::ensure!(!series[0].x.is_empty(), "no direction could be scored");
    Ok(LinePlot {
        name: format!("extrapolation-direction-{}", shape.name),
        title: format!(
            "nnwarp / {}/neo-hookean: error as the field's azimuth α leaves [0, π/2] (β = {})",
            shape.name, FIELD_ANGLES.1
        ),
        x_label: "field azimuth α (rad)".into(),
        y_label: "rel-error".into(),
        log_y: true,
        series,
    })
}

/// NNWarp Fig. 15: the beam's tip node over time under a suddenly applied field, full
/// Neo-Hookean implicit Euler against NNWarp's runtime and linear FEM at time step `dt`.
/// Returns the plot and a note with each method's mean `rel-error` over the frames.
pub(super) fn trajectory(
    model: &Path,
    direction: Vector3<f64>,
    dt: f64,
    size: Size,
) -> crate::Result<(LinePlot, String)> {
    use weft_sim::scenes::volume::{ForceField, VolumeSolve};
    let quick = size == Size::Quick;
    let mut scene = weft_sim::VolumeScene::builtin("beam-neo-hookean-field", quick)?;
    scene.young = YOUNG;
    scene.poisson = POISSON;
    scene.density = DENSITY;
    scene.solve = VolumeSolve::ImplicitEuler { dt };
    scene.frames = ((if quick { 0.3 } else { 1.5 }) / dt).round() as usize;
    // The field's strength: the static linear answer at the middle load.
    let probe = weft_sim::VolumeSimulation::new(scene.clone(), None)?;
    let shape = Shape {
        name: "beam",
        mesh: probe.mesh().clone(),
        anchors: probe.anchors().to_vec(),
        split: "train-shape",
    };
    let lame = LameParameters::from_young_poisson(YOUNG, POISSON)?;
    let bench = Bench::new(&shape, direction, lame)?;
    let acceleration = 1.0 / (bench.reach * bench.scale);
    scene.gravity = None;
    scene.force_field = Some(ForceField::Directional {
        direction: direction.into(),
        acceleration,
    });
    let mut full = weft_sim::VolumeSimulation::new(scene.clone(), None)?;
    let mut linear_scene = scene.clone();
    linear_scene.material = Material::Linear;
    let mut linear = weft_sim::VolumeSimulation::new(linear_scene, None)?;
    let (_, mlp) = load_model(model)?;
    let mut runtime = NnWarpSimulation::new(&full, mlp)?;
    // The tip node nearest the tip face's centre.
    let mesh = full.mesh();
    let x_max = mesh.positions().iter().map(|p| p.x).fold(f64::MIN, f64::max);
    let centre = mesh
        .positions()
        .iter()
        .filter(|p| (p.x - x_max).abs() < 1e-9)
        .fold(Vector3::zeros(), |a, p| a + p)
        / mesh
            .positions()
            .iter()
            .filter(|p| (p.x - x_max).abs() < 1e-9)
            .count()
            .max(1) as f64;
    let tip = (0..mesh.num_vertices())
        .min_by(|&a, &b| {
            (mesh.positions()[a] - centre)
                .norm()
                .total_cmp(&(mesh.positions()[b] - centre).norm())
        })
        .context("empty mesh")?;
    let along = |u: &[f64]| Vector3::new(u[3 * tip], u[3 * tip + 1], u[3 * tip + 2]).dot(&direction);
    let labels = ["full FEM (neo-hookean)", "nnwarp", "linear"];
    let mut series: Vec<Series> = labels
        .iter()
        .map(|l| Series {
            label: l.to_string(),
            x: vec![0.0],
            y: vec![0.0],
        })
        .collect();
    // The runtime against full FEM with the linear solve beside it, frame by frame: the
    // loop `cargo xtask warp --reference` runs too.
    let twins = ReferenceTwins {
        reference: &mut full,
        others: vec![&mut linear],
    };
    let report = run_against_reference(&mut runtime, Some(twins), scene.frames, |f| -> crate::Result<()> {
        let truth = f.reference.context("a run with a reference has its frames")?;
        for (s, u) in series.iter_mut().zip([truth, &f.runtime.warped, &f.others[0]]) {
            s.x.push(f.frame as f64 * dt);
            s.y.push(along(u));
        }
        Ok(())
    })?;
    let (e_nnwarp, e_linear) = report.frames.iter().fold((0.0, 0.0), |(n, l), f| {
        (n + f.nnwarp.unwrap_or(f64::NAN), l + f.others[0])
    });
    let frames = scene.frames.max(1) as f64;
    let note = format!(
        "nnwarp/trajectory at Δt = {dt} s: beam tip node {tip}, {} frames under a field of {acceleration:.3} m/s² \
         applied at t = 0 (static linear answer 1 unit-sphere unit); mean rel-error over the frames: nnwarp {:.4}, \
         linear {:.4}",
        scene.frames,
        e_nnwarp / frames,
        e_linear / frames
    );
    Ok((
        LinePlot {
            name: format!("trajectory-dt-{}ms", (dt * 1e3).round()),
            title: format!("nnwarp / beam: tip node along the field over time, Δt = {dt} s"),
            x_label: "time (s)".into(),
            y_label: "tip displacement along the field (m)".into(),
            log_y: false,
            series,
        },
        note,
    ))
}

/// NNWarp Table 1's columns for one body, all measured here: tets, factorisation, one
/// static solve, the Neo-Hookean network's correction (means over `REPEATS`), frames per
/// second of the two together, and one full Neo-Hookean implicit-Euler frame (Δt = 0.01 s).
/// Each is a record (scene `{body}/neo-hookean`) with the paper's figure beside it where
/// it prints one; the row is `paper / ours` from those records.
fn timing_row(
    out: &mut ExperimentOutput,
    shape: &Shape,
    model: &std::path::Path,
    lame: LameParameters,
    paper: &PaperTiming,
) -> crate::Result<Vec<String>> {
    const REPEATS: usize = 20;
    let mesh = &shape.mesh;
    let rest = mesh.flat_positions();
    let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), DENSITY);
    let fixed = weft_sim::anchors::fixed_dofs(mesh.num_vertices(), &shape.anchors)?;
    let gravity = weft_sim::energies::ConstantForce::gravity(&masses, [0.0, -9.81, 0.0])?;
    let forces = gravity.forces().to_vec();
    let linear_energy = TetElasticity::new(mesh, Material::Linear, lame)?;
    let mut linear = PrefactorizedLinear::new(
        &rest,
        &[&linear_energy],
        masses.clone(),
        fixed.clone(),
        LinearSolve::Static,
    )?;
    let (_, mlp) = load_model(model)?;
    let context = WarpContext::new(
        mesh,
        &shape.anchors,
        FieldDirection::Directional(-Vector3::y()),
        POISSON,
    )?;
    let nnwarp = NnWarp::new(context, mlp);
    let (mut solve, mut correction) = (0.0, 0.0);
    for _ in 0..REPEATS {
        let t = Instant::now();
        linear.step(&forces, &[])?;
        solve += t.elapsed().as_secs_f64();
        let t = Instant::now();
        std::hint::black_box(nnwarp.warp(linear.displacements())?);
        correction += t.elapsed().as_secs_f64();
    }
    let (solve, correction) = (solve / REPEATS as f64, correction / REPEATS as f64);
    let terms: Vec<Box<dyn weft_sim::Energy>> = vec![
        Box::new(TetElasticity::new(mesh, Material::NeoHookean, lame)?),
        Box::new(gravity),
    ];
    let mut full = weft_sim::ImplicitEuler::new(masses, 0.01, rest, terms, fixed)?;
    let t = Instant::now();
    full.step(&[])?;
    let full_seconds = t.elapsed().as_secs_f64();
    let scene = format!("{}/neo-hookean", shape.name);
    let frame = Timing::new(solve + correction, full_seconds);
    let none = Timing::default();
    let tets = mesh.num_tets() as f64;
    let factorization = linear.factorization_seconds();
    let fps = 1.0 / (solve + correction);
    for (method, metric, value, unit, timing, paper_value) in [
        (
            "prefactorized-linear",
            "tetrahedra",
            tets,
            "count",
            none,
            Some(paper.tetrahedra),
        ),
        (
            "prefactorized-linear",
            "factorization-seconds",
            factorization,
            "s",
            none,
            Some(paper.factorization),
        ),
        (
            "prefactorized-linear",
            "solve-seconds",
            solve,
            "s",
            Timing::new(solve, full_seconds),
            paper.solve,
        ),
        ("nnwarp", "correction-seconds", correction, "s", frame, None),
        ("nnwarp", "fps", fps, "1/s", frame, paper.fps),
        (
            "neo-hookean",
            "frame-seconds",
            full_seconds,
            "s",
            Timing::new(full_seconds, full_seconds),
            None,
        ),
    ] {
        out.record(&scene, method, metric, value, unit, timing);
        out.split(shape.split);
        if let Some(p) = paper_value {
            out.paper(p);
        }
    }
    let ms = crate::paper::format_ms;
    let [p_tets, p_factor, p_solve, p_fps] = paper.printed;
    Ok(vec![
        format!("{} / `{}`", paper.model, shape.name),
        format!("{p_tets} / {tets:.0}"),
        format!("{p_factor} / {}", ms(factorization)),
        format!("{p_solve} / {}", ms(solve)),
        ms(correction),
        format!("{p_fps} / {fps:.0}"),
        ms(full_seconds),
    ])
}
