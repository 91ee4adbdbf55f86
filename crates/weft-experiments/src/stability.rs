//! `cargo xtask stability`: the measured stability map. Every simulator is swept over a
//! grid of extreme parameters and each cell's outcome is recorded: converged (with its
//! Newton iterations, worst residual, time and error against a run with a 1000× tighter
//! Newton tolerance), converged with a clamp (a fallback diagonal shift, a step retried
//! with the other Hessian strategy, or the residual's round-off floor was needed), or a
//! typed error. A panic or a non-finite value passed on
//! is a failure, and the command exits non-zero if any cell fails. `docs/STABILITY.md`
//! holds the committed map.

use std::collections::HashMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::Context;
use plotters::coord::Shift;
use plotters::prelude::*;
use serde::Serialize;
use weft_mesh::generators::{BeamParams, beam};
use weft_proj::{InextensibilityLayer, QuasistaticLayer, QuasistaticParams, SocpSettings, ZeroLengthScaling};
use weft_sim::energies::{ConstantForce, LameParameters, Material, TetElasticity};
use weft_sim::scenes::cloth::{ClothModel, MeshSpec, Motion, MotionSegment};
use weft_sim::{ClothScene, ClothSimulation, Energy, HessianProjection, ImplicitEuler};

use crate::records::distinct;
use crate::records::{Record, validate};
use weft_data::files::{progress_bar, write_json, write_text};

/// How the stability map runs (`cargo xtask stability`).
#[derive(Debug, Clone)]
pub struct StabilityOptions {
    /// The small grid CI runs (coarse meshes, three values per axis).
    pub quick: bool,
    /// Output directory: results.json (tidy records), cells.json (every cell with its error
    /// message), stability.md, and heat maps under plots/.
    pub out: PathBuf,
    /// Hide the progress bar.
    pub quiet: bool,
}

/// What happened in one cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    Converged,
    /// Converged, but a diagonal shift or the residual's round-off floor was needed.
    Clamped,
    /// A typed error (non-convergence, invalid parameter, degenerate input).
    TypedError,
    /// A panic or a non-finite value passed on: a bug.
    Failure,
}

impl Outcome {
    pub fn code(self) -> f64 {
        match self {
            Self::Converged => 0.0,
            Self::Clamped => 1.0,
            Self::TypedError => 2.0,
            Self::Failure => 3.0,
        }
    }
}

/// One cell of the map.
#[derive(Debug, Clone, Serialize)]
pub struct Cell {
    /// The simulator and what is held fixed, e.g. `cloth-mass-spring-n17`.
    pub family: String,
    /// The swept parameters, e.g. `k-1e5-dt-1e-3`.
    pub key: String,
    /// Row and column labels for the heat map, and the panel it belongs to.
    pub row: String,
    pub col: String,
    pub panel: String,
    pub outcome: Outcome,
    pub iterations: Option<f64>,
    pub residual: Option<f64>,
    pub seconds: Option<f64>,
    pub error_vs_tighter: Option<f64>,
    pub message: Option<String>,
}

/// What a converged run reports.
struct Run {
    positions: Vec<f64>,
    iterations: f64,
    residual: f64,
    seconds: f64,
    clamped: bool,
}

fn tag(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if v.abs() >= 1e-2 && v.abs() < 1e3 {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Runs `f` twice (normal and 1000× tighter tolerance) and classifies the outcome.
fn cell(
    family: &str,
    key: String,
    (panel, row, col): (String, String, String),
    f: impl Fn(f64) -> crate::Result<Run>,
) -> Cell {
    let mut c = Cell {
        family: family.into(),
        key,
        row,
        col,
        panel,
        outcome: Outcome::Converged,
        iterations: None,
        residual: None,
        seconds: None,
        error_vs_tighter: None,
        message: None,
    };
    let run = |factor| match catch_unwind(AssertUnwindSafe(|| f(factor))) {
        Ok(r) => r.map_err(|e| (Outcome::TypedError, format!("{e:#}"))),
        Err(p) => Err((
            Outcome::Failure,
            format!(
                "panic: {}",
                p.downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default()
            ),
        )),
    };
    match run(1.0) {
        Ok(r) => {
            if r.positions.iter().any(|v| !v.is_finite()) {
                c.outcome = Outcome::Failure;
                c.message = Some("a non-finite position was returned".into());
                return c;
            }
            c.outcome = if r.clamped {
                Outcome::Clamped
            } else {
                Outcome::Converged
            };
            c.iterations = Some(r.iterations);
            c.residual = Some(r.residual);
            c.seconds = Some(r.seconds);
            if let Ok(t) = run(1e-3) {
                c.error_vs_tighter = Some(weft_linalg::max_abs(
                    r.positions.iter().zip(&t.positions).map(|(a, b)| a - b),
                ));
            }
        }
        Err((o, m)) => {
            c.outcome = o;
            c.message = Some(m);
        }
    }
    c
}

/// Inexact steps of a cloth run (docs/CLOTH.md, "Inexact steps"): Newton iterations per
/// step on projected Hessians, and how many of them may factorise (`None`: all).
#[derive(Debug, Clone, Copy)]
struct Inexact {
    iterations: usize,
    factorizations: Option<usize>,
}

/// Cloth of either model: `steps` implicit-Euler steps of a violently grasped sheet,
/// solved to the tolerance or, with `inexact`, by a fixed number of iterations.
fn cloth_run(
    model: &str,
    n: usize,
    k: f64,
    dt: f64,
    steps: usize,
    inexact: Option<Inexact>,
    tol_factor: f64,
) -> crate::Result<Run> {
    let mut s = ClothScene::builtin(if model == "fem" { "sheet-fem" } else { "sheet-ms" }, false)?;
    s.mesh = MeshSpec::Sheet { n, size: 1.0 };
    s.model = match model {
        "fem" => ClothModel::Fem {
            young: k,
            poisson: 0.3,
            bend_stiffness: 1e-7 * k,
        },
        _ => ClothModel::MassSpring {
            stretch_stiffness: k,
            bend_stiffness: 0.02 * k,
        },
    };
    // A violent grasp: 0.3 m at 2 Hz, peak speed 3.8 m/s.
    s.program = vec![MotionSegment {
        motion: Motion::TranslateX,
        amplitude: 0.3,
        period: 0.5,
        cycles: 1.0,
    }];
    s.dt = dt;
    s.frames = steps;
    s.relative_tolerance *= tol_factor;
    if let Some(inexact) = inexact {
        s.hessian = Some(HessianProjection::Always);
        s.newton_budget = Some(inexact.iterations);
        s.newton_factorizations = inexact.factorizations;
    }
    let mut sim = ClothSimulation::new(s, None)?;
    // A diagonal shift is a clamp only where it is a fallback: with `Never` (mass-spring
    // cloth's default) shifting the exact Hessian is the strategy itself.
    let shift_is_fallback = sim.integrator().settings.projection != HessianProjection::Never;
    let (mut its, mut res, mut secs, mut clamped) = (0.0, 0.0f64, 0.0, false);
    for _ in 0..steps {
        let f = sim.step()?;
        its += f.report.newton.iterations as f64;
        res = res.max(f.report.newton.residual);
        secs += f.report.seconds;
        clamped |= (shift_is_fallback && f.report.newton.regularizations > 0)
            || f.report.newton.fallback.is_some()
            || f.report.newton.residual_floor > sim.integrator().settings.tolerance;
    }
    Ok(Run {
        positions: sim.integrator().positions().to_vec(),
        iterations: its / steps as f64,
        residual: res,
        seconds: secs / steps as f64,
        clamped,
    })
}

/// A small clamped beam of `material` under gravity from a rest, inverted or sliver start.
fn tet_run(
    material: Material,
    e: f64,
    nu: f64,
    dt: f64,
    start: &str,
    steps: usize,
    tol_factor: f64,
) -> crate::Result<Run> {
    let mesh = beam(&BeamParams {
        cells: [4, 2, 2],
        size: [0.4, 0.1, 0.1],
    })?;
    let lame = LameParameters::from_young_poisson(e, nu)?;
    let elastic = TetElasticity::new(&mesh, material, lame)?;
    let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), 1000.0);
    let gravity = ConstantForce::gravity(&masses, [0.0, 0.0, -9.81])?;
    let anchors = weft_sim::anchors::nodes_at_min(mesh.positions(), 0, 1e-9)?;
    let fixed = weft_sim::anchors::fixed_dofs(mesh.num_vertices(), &anchors)?;
    let mut x0 = mesh.flat_positions();
    let p = mesh.positions();
    match start {
        // The free end mirrored through its mid-plane: every tet there inverted.
        "inverted" => {
            for (v, q) in p.iter().enumerate() {
                if q.x > 0.3 - 1e-9 {
                    x0[3 * v + 2] = 0.1 - q.z;
                }
            }
        }
        // One node pushed onto the plane of its tet's opposite face: a zero-volume sliver.
        "sliver" => {
            let t = mesh.tets()[mesh.num_tets() - 1];
            let (a, b, c) = (p[t[1]], p[t[2]], p[t[3]]);
            let n = (b - a).cross(&(c - a)).normalize();
            let d = p[t[0]] - n * (p[t[0]] - a).dot(&n);
            if !anchors.contains(&t[0]) {
                x0[3 * t[0]..3 * t[0] + 3].copy_from_slice(d.as_slice());
            }
        }
        _ => {}
    }
    let terms: Vec<Box<dyn Energy>> = vec![Box::new(elastic), Box::new(gravity)];
    let mut ie = ImplicitEuler::new(masses, dt, x0.clone(), terms, fixed)?;
    ie.settings.tolerance *= tol_factor;
    let hold = weft_sim::anchors::hold(&anchors, &x0);
    let (mut its, mut res, mut secs, mut clamped) = (0.0, 0.0f64, 0.0, false);
    for _ in 0..steps {
        let r = ie.step(&hold)?;
        its += r.newton.iterations as f64;
        res = res.max(r.newton.residual);
        secs += r.seconds;
        clamped |= r.newton.regularizations > 0
            || r.newton.fallback.is_some()
            || r.newton.residual_floor > ie.settings.tolerance;
    }
    Ok(Run {
        positions: ie.positions().to_vec(),
        iterations: its / steps as f64,
        residual: res,
        seconds: secs / steps as f64,
        clamped,
    })
}

/// A stretched (or collapsed, `stretch < 0`) noisy prediction of a flat sheet.
/// `frames` frames of the `limb-jiggle` tissue on the quick limb with the fat layer's
/// modulus `fat` (Pa) and the motion scaled by `amplitude`.
fn tissue_run(fat: f64, amplitude: f64, frames: usize, tol_factor: f64) -> crate::Result<Run> {
    use weft_sim::scenes::soft_tissue::{SoftTissue, SoftTissueParams};
    let params = SoftTissueParams {
        young: fat,
        motion_amplitude: amplitude,
        ..SoftTissueParams::jiggle()
    };
    let t = Instant::now();
    let mut body = SoftTissue::new(weft_mesh::limb::limb(&weft_mesh::limb::LimbParams::quick())?, params)?;
    body.newton_settings_mut().tolerance *= tol_factor;
    let tolerance = body.newton_settings_mut().tolerance;
    let (mut its, mut res, mut steps, mut clamped) = (0.0, 0.0f64, 0usize, false);
    for _ in 0..frames {
        for r in body.step_frame()?.steps {
            its += r.newton.iterations as f64;
            res = res.max(r.newton.residual);
            steps += 1;
            clamped |=
                r.newton.regularizations > 0 || r.newton.fallback.is_some() || r.newton.residual_floor > tolerance;
        }
    }
    Ok(Run {
        positions: body.positions().to_vec(),
        iterations: its / steps.max(1) as f64,
        residual: res,
        seconds: t.elapsed().as_secs_f64(),
        clamped,
    })
}

fn prediction(rest: &weft_mesh::TriMesh, stretch: f64) -> Vec<f64> {
    let mut state: u64 = 0x5EED;
    let h = 1.0 / ((rest.num_vertices() as f64).sqrt() - 1.0);
    rest.positions()
        .iter()
        .flat_map(|p| {
            let mut noise = || {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.1 * h
            };
            if stretch < 0.0 {
                [0.25, 0.25, 0.25]
            } else {
                [
                    (1.0 + stretch) * p.x + noise(),
                    (1.0 + stretch) * p.y + noise(),
                    noise(),
                ]
            }
        })
        .collect()
}

/// One cell of the map, run when the sweep reaches it.
type Job = Box<dyn Fn() -> Cell + Send>;

/// Cloth: stiffness × Δt × resolution, both models, and the inexact steps.
fn cloth_jobs(quick: bool, jobs: &mut Vec<Job>) {
    let (ks, dts, ns): (Vec<f64>, Vec<f64>, Vec<usize>) = if quick {
        (vec![1e1, 1e5, 1e9], vec![1e-5, 1e-3, 1e-1], vec![9])
    } else {
        (
            vec![1e1, 1e3, 1e5, 1e7, 1e9],
            vec![1e-5, 1e-4, 1e-3, 1e-2, 1e-1],
            vec![17, 33, 65],
        )
    };
    let steps = if quick { 2 } else { 3 };
    for model in ["mass-spring", "fem"] {
        for &n in &ns {
            for &k in &ks {
                for &dt in &dts {
                    let family = format!("cloth-{model}-n{n}");
                    jobs.push(Box::new(move || {
                        cell(
                            &family,
                            format!("k-{}-dt-{}", tag(k), tag(dt)),
                            (
                                format!("{n}×{n}"),
                                format!("k = {}", tag(k)),
                                format!("Δt = {}", tag(dt)),
                            ),
                            |f| cloth_run(model, n, k, dt, steps, None, f),
                        )
                    }));
                }
            }
        }
    }
    // Inexact steps on the mass-spring sheet of the middle resolution: one projected
    // iteration per step (Baraff & Witkin), and four chord iterations on one
    // factorisation. Stopping at the budget is their design, not a clamp.
    let n = ns[ns.len() / 2];
    for (variant, inexact) in [
        (
            "inexact",
            Inexact {
                iterations: 1,
                factorizations: None,
            },
        ),
        (
            "chord",
            Inexact {
                iterations: 4,
                factorizations: Some(1),
            },
        ),
    ] {
        for &k in &ks {
            for &dt in &dts {
                let family = format!("cloth-mass-spring-{variant}-n{n}");
                jobs.push(Box::new(move || {
                    cell(
                        &family,
                        format!("k-{}-dt-{}", tag(k), tag(dt)),
                        (
                            format!("{n}×{n}, {} iteration(s) per step", inexact.iterations),
                            format!("k = {}", tag(k)),
                            format!("Δt = {}", tag(dt)),
                        ),
                        |f| cloth_run("mass-spring", n, k, dt, steps, Some(inexact), f),
                    )
                }));
            }
        }
    }
}

/// Tet FEM: material × E × ν × Δt × start.
fn tet_jobs(quick: bool, jobs: &mut Vec<Job>) {
    let (es, nus, tdts) = if quick {
        (vec![1e3, 1e9], vec![0.0, 0.499], vec![1e-5, 1e-1])
    } else {
        (
            vec![1e3, 1e5, 1e7, 1e9],
            vec![0.0, 0.3, 0.45, 0.499],
            vec![1e-5, 1e-3, 1e-1],
        )
    };
    for (material, mname) in [
        (Material::Linear, "linear"),
        (Material::CoRotational, "corotational"),
        (Material::StVK, "stvk"),
        (Material::NeoHookean, "neo-hookean"),
    ] {
        for start in ["rest", "inverted", "sliver"] {
            for &e in &es {
                for &nu in &nus {
                    for &dt in &tdts {
                        let family = format!("tet-{mname}");
                        jobs.push(Box::new(move || {
                            cell(
                                &family,
                                format!("e-{}-nu-{}-dt-{}-start-{start}", tag(e), tag(nu), tag(dt)),
                                (
                                    format!("{start} start, Δt = {}", tag(dt)),
                                    format!("E = {}", tag(e)),
                                    format!("ν = {}", tag(nu)),
                                ),
                                |f| tet_run(material, e, nu, dt, start, 2, f),
                            )
                        }));
                    }
                }
            }
        }
    }
}

/// Soft tissue (the `limb-jiggle` scene on the quick limb): fat modulus × motion
/// amplitude, through jumps and the first abrupt stop.
fn tissue_jobs(quick: bool, jobs: &mut Vec<Job>) {
    let (fats, amplitudes) = if quick {
        (vec![1e3, 1.5e3], vec![1.0, 2.0])
    } else {
        (vec![5e2, 1e3, 1.5e3, 3e3], vec![0.5, 1.0, 1.5, 2.0])
    };
    for &fat in &fats {
        for &amplitude in &amplitudes {
            jobs.push(Box::new(move || {
                cell(
                    "soft-tissue-jiggle",
                    format!("fat-{}-amplitude-{}", tag(fat), tag(amplitude)),
                    (
                        "quick limb, dynamic motion".into(),
                        format!("fat E = {}", tag(fat)),
                        format!("amplitude × {}", tag(amplitude)),
                    ),
                    |f| tissue_run(fat, amplitude, if quick { 12 } else { 30 }, f),
                )
            }));
        }
    }
}

/// Projection layers: stretch 0–200 % (−1: collapsed to a point) × ε or μ.
fn projection_jobs(quick: bool, jobs: &mut Vec<Job>) {
    let n = if quick { 7 } else { 13 };
    let stretches = [-1.0, 0.0, 0.1, 0.5, 1.0, 2.0];
    for &s in &stretches {
        let row = if s < 0.0 {
            "collapsed".to_string()
        } else {
            format!("stretch {} %", 100.0 * s)
        };
        for &eps in &[0.0, 0.01, 0.1, 1.0] {
            let row = row.clone();
            jobs.push(Box::new(move || {
                cell(
                    "socp",
                    format!("stretch-{}-eps-{}", tag(s), tag(eps)),
                    (format!("{n}×{n} sheet"), row.clone(), format!("ε = {}", tag(eps))),
                    |f| {
                        let rest = weft_mesh::generators::sheet(n, 1.0)?;
                        let settings = SocpSettings {
                            tolerance: 1e-8 * f,
                            ..SocpSettings::default()
                        };
                        let layer = InextensibilityLayer::new(&rest, eps, settings)?;
                        let t = Instant::now();
                        let (sol, report) = layer.forward(&prediction(&rest, s))?;
                        Ok(Run {
                            positions: sol.into_positions(),
                            iterations: report.iterations as f64,
                            residual: report.kkt_residual,
                            seconds: t.elapsed().as_secs_f64(),
                            // The interior-point point returned because the polish was
                            // rejected while edges are at their bound (with none active there
                            // is nothing to polish).
                            clamped: report.polish_iterations.is_none() && report.active_constraints > 0,
                        })
                    },
                )
            }));
        }
        for &mu in &[1e-4, 1e-2, 1.0, 1e2] {
            let row = row.clone();
            jobs.push(Box::new(move || {
                cell(
                    "quasistatic",
                    format!("stretch-{}-mu-{}", tag(s), tag(mu)),
                    (format!("{n}×{n} sheet"), row.clone(), format!("μ = {}", tag(mu))),
                    |f| {
                        let rest = weft_mesh::generators::sheet(n, 1.0)?;
                        let params = QuasistaticParams {
                            tolerance: 1e-8 * f,
                            ..QuasistaticParams::default()
                        };
                        let layer = QuasistaticLayer::new(&rest, params)?;
                        let (sol, report) = layer.forward(&prediction(&rest, s), &ZeroLengthScaling::Global(mu))?;
                        Ok(Run {
                            positions: sol.into_positions(),
                            iterations: report.newton.iterations as f64,
                            residual: report.newton.residual,
                            seconds: report.time_seconds,
                            clamped: report.newton.regularizations > 0,
                        })
                    },
                )
            }));
        }
    }
}

/// Sweeps every simulator over the grid and writes the map; a failing cell (a panic or a
/// NaN passed on) is an error after everything is written.
pub fn run(args: &StabilityOptions) -> crate::Result<()> {
    let quick = args.quick;
    let start = Instant::now();
    let mut jobs: Vec<Job> = Vec::new();
    cloth_jobs(quick, &mut jobs);
    tet_jobs(quick, &mut jobs);
    tissue_jobs(quick, &mut jobs);
    projection_jobs(quick, &mut jobs);

    let bar = progress_bar(args.quiet, jobs.len() as u64, "stability", "cells")?;
    // Panics are caught per cell; keep the default hook from printing each one.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let cells: Vec<Cell> = jobs
        .into_iter()
        .map(|j| {
            let c = j();
            bar.inc(1);
            c
        })
        .collect();
    std::panic::set_hook(hook);
    bar.finish_and_clear();
    write_outputs(&args.out, &cells, quick, start.elapsed().as_secs_f64())?;
    let failures: Vec<&Cell> = cells.iter().filter(|c| c.outcome == Outcome::Failure).collect();
    let count = |o| cells.iter().filter(|c| c.outcome == o).count();
    eprintln!(
        "stability: {} cells in {:.0} s — {} converged, {} clamped, {} typed errors, {} failures → {}",
        cells.len(),
        start.elapsed().as_secs_f64(),
        count(Outcome::Converged),
        count(Outcome::Clamped),
        count(Outcome::TypedError),
        failures.len(),
        args.out.display()
    );
    if !failures.is_empty() {
        crate::error::bail!(
            "{} cell(s) failed (a panic or a NaN passed on): {}",
            failures.len(),
            failures
                .iter()
                .map(|c| format!("{}/{}: {}", c.family, c.key, c.message.as_deref().unwrap_or("")))
                .collect::<Vec<_>>()
                .join("; ")
        );
    }
    Ok(())
}

fn write_outputs(out: &std::path::Path, cells: &[Cell], quick: bool, seconds: f64) -> crate::Result<()> {
    std::fs::create_dir_all(out.join("plots")).with_context(|| format!("creating {}", out.display()))?;
    let mut records = Vec::new();
    for c in cells {
        let mut push = |metric: &str, value: Option<f64>, unit: &str| {
            if let Some(v) = value.filter(|v| v.is_finite()) {
                records.push(Record {
                    experiment: "stability".into(),
                    scene: c.family.clone(),
                    method: c.key.clone(),
                    metric: metric.into(),
                    split: None,
                    value: v,
                    unit: unit.into(),
                    paper_value: None,
                    seconds_per_frame: None,
                    ground_truth_seconds_per_frame: None,
                    seed: None,
                });
            }
        };
        push("outcome", Some(c.outcome.code()), "code");
        push("newton-iterations", c.iterations, "count");
        push("residual", c.residual, "N");
        push("seconds-per-step", c.seconds, "s");
        push("error-vs-tighter", c.error_vs_tighter, "m");
    }
    validate(&records)?;
    write_json(&out.join("results.json"), &records)?;
    write_json(&out.join("cells.json"), &cells)?;
    // Heat maps: one per family, one panel per value of the held axis.
    let families = distinct(cells.iter().map(|c| c.family.as_str()));
    let mut md = format!(
        "# Stability map ({} grid)\n\nProduced by `cargo xtask stability{}` in {seconds:.0} s. Outcome per cell: \
         **C** converged, **K** converged with a clamp (a diagonal shift as a fallback, a step retried with the \
         other Hessian strategy, the residual's round-off floor, or an SOCP point handed over unpolished with edges \
         at their bound), **E** a typed error, **F** a failure (a panic or a NaN passed on). The number is the \
         mean Newton (or interior-point) iterations per step.\n\n",
        if quick { "quick" } else { "full" },
        if quick { " --quick" } else { "" }
    );
    let mut summary: Vec<(String, [usize; 4])> = Vec::new();
    for f in &families {
        let fc: Vec<&Cell> = cells.iter().filter(|c| c.family == *f).collect();
        let mut n = [0usize; 4];
        for c in &fc {
            n[c.outcome.code() as usize] += 1;
        }
        summary.push((f.to_string(), n));
        heat_map(&out.join("plots").join(format!("stability-{f}")), f, &fc)?;
        md.push_str(&format!("## {f}\n\n![{f}](plots/stability-{f}.svg)\n\n"));
        let panels = distinct(fc.iter().map(|c| c.panel.as_str()));
        for p in panels {
            let pc: Vec<&&Cell> = fc.iter().filter(|c| c.panel == p).collect();
            let rows = distinct(pc.iter().map(|c| c.row.as_str()));
            let cols = distinct(pc.iter().map(|c| c.col.as_str()));
            md.push_str(&format!(
                "**{p}**\n\n| | {} |\n|{}\n",
                cols.join(" | "),
                "---|".repeat(cols.len() + 1)
            ));
            for r in &rows {
                let cells_in_row: Vec<String> = cols
                    .iter()
                    .map(|col| {
                        pc.iter().find(|c| c.row == *r && c.col == *col).map_or("".into(), |c| {
                            let letter = ["C", "K", "E", "F"][c.outcome.code() as usize];
                            c.iterations.map_or(letter.to_string(), |i| format!("{letter} {i:.1}"))
                        })
                    })
                    .collect();
                md.push_str(&format!("| {r} | {} |\n", cells_in_row.join(" | ")));
            }
            md.push('\n');
        }
        let errors: HashMap<String, usize> =
            fc.iter()
                .filter_map(|c| c.message.clone())
                .fold(HashMap::new(), |mut m, msg| {
                    let short: String = msg.chars().take(90).collect();
                    *m.entry(short).or_default() += 1;
                    m
                });
        if !errors.is_empty() {
            let mut e: Vec<_> = errors.into_iter().collect();
            e.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
            md.push_str("Errors (first 90 characters, with counts):\n\n");
            for (msg, k) in e.iter().take(8) {
                md.push_str(&format!("- {k} × `{}`\n", msg.replace('`', "'")));
            }
            md.push('\n');
        }
    }
    let mut head = String::from("| family | converged | clamped | typed error | failure |\n|---|---|---|---|---|\n");
    for (f, n) in &summary {
        head.push_str(&format!("| `{f}` | {} | {} | {} | {} |\n", n[0], n[1], n[2], n[3]));
    }
    let md = md.replacen("\n\n## ", &format!("\n\n{head}\n## "), 1);
    write_text(&out.join("stability.md"), &md)?;
    Ok(())
}

fn heat_map_on<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, title: &str, cells: &[&Cell]) -> crate::Result<()>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| crate::Error::plot(e);
    root.fill(&WHITE).map_err(e)?;
    let root = root.titled(title, ("sans-serif", 20)).map_err(e)?;
    let panels = crate::records::distinct(cells.iter().map(|c| c.panel.as_str()));
    let per_row = panels.len().min(3);
    let grid_rows = panels.len().div_ceil(per_row);
    let areas = root.split_evenly((grid_rows, per_row));
    for (panel, area) in panels.iter().zip(areas) {
        let pc: Vec<&&Cell> = cells.iter().filter(|c| c.panel == *panel).collect();
        let rows = crate::records::distinct(pc.iter().map(|c| c.row.as_str()));
        let cols = crate::records::distinct(pc.iter().map(|c| c.col.as_str()));
        let (w, h) = area.dim_in_pixel();
        let (left, top) = (110i32, 44i32);
        let cw = ((w as i32 - left - 8) / cols.len().max(1) as i32).max(10);
        let ch = ((h as i32 - top - 8) / rows.len().max(1) as i32).clamp(10, 40);
        area.draw(&Text::new(panel.to_string(), (4, 4), ("sans-serif", 14).into_font()))
            .map_err(e)?;
        for (j, col) in cols.iter().enumerate() {
            area.draw(&Text::new(
                col.to_string(),
                (left + j as i32 * cw + 2, 24),
                ("sans-serif", 11).into_font(),
            ))
            .map_err(e)?;
        }
        for (i, row) in rows.iter().enumerate() {
            let y = top + i as i32 * ch;
            area.draw(&Text::new(
                row.to_string(),
                (4, y + ch / 2 - 6),
                ("sans-serif", 11).into_font(),
            ))
            .map_err(e)?;
            for (j, col) in cols.iter().enumerate() {
                let Some(c) = pc.iter().find(|c| c.row == *row && c.col == *col) else {
                    continue;
                };
                let colour = match c.outcome {
                    Outcome::Converged => RGBColor(110, 180, 110),
                    Outcome::Clamped => RGBColor(235, 200, 80),
                    Outcome::TypedError => RGBColor(170, 170, 190),
                    Outcome::Failure => RGBColor(210, 40, 40),
                };
                let x = left + j as i32 * cw;
                area.draw(&Rectangle::new([(x, y), (x + cw - 2, y + ch - 2)], colour.filled()))
                    .map_err(e)?;
                let label = match (c.outcome, c.iterations) {
                    (Outcome::TypedError, _) => "error".to_string(),
                    (Outcome::Failure, _) => "FAIL".to_string(),
                    (_, Some(it)) => format!("{it:.1}"),
                    _ => String::new(),
                };
                area.draw(&Text::new(
                    label,
                    (x + 4, y + ch / 2 - 6),
                    ("sans-serif", 11).into_font(),
                ))
                .map_err(e)?;
            }
        }
    }
    root.present().map_err(e)?;
    Ok(())
}

/// A stability heat map: one panel per held value, cells coloured by outcome (green
/// converged, yellow clamped, grey typed error, red failure) and labelled with the mean
/// iterations per step.
fn heat_map(stem: &Path, title: &str, cells: &[&Cell]) -> crate::Result<()> {
    crate::report::plots::both(stem, |r| heat_map_on(r, title, cells), |r| heat_map_on(r, title, cells))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run_with(positions: Vec<f64>, clamped: bool) -> crate::Result<Run> {
        Ok(Run {
            positions,
            iterations: 2.0,
            residual: 1e-9,
            seconds: 0.0,
            clamped,
        })
    }

    #[test]
    fn panics_and_nan_are_failures_errors_are_typed_and_clamps_are_seen() {
        let labels = || ("p".to_string(), "r".to_string(), "c".to_string());
        let hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        let panicked = cell("f", "k".into(), labels(), |_| -> crate::Result<Run> { panic!("boom") });
        std::panic::set_hook(hook);
        assert_eq!(panicked.outcome, Outcome::Failure);
        assert!(panicked.message.unwrap().contains("boom"));
        let nan = cell("f", "k".into(), labels(), |_| run_with(vec![0.0, f64::NAN], false));
        assert_eq!(nan.outcome, Outcome::Failure);
        let typed = cell("f", "k".into(), labels(), |_| -> crate::Result<Run> {
            crate::error::bail!("not converged")
        });
        assert_eq!(typed.outcome, Outcome::TypedError);
        let clamped = cell("f", "k".into(), labels(), |_| run_with(vec![1.0], true));
        assert_eq!(clamped.outcome, Outcome::Clamped);
        // The tighter run's difference is measured.
        let ok = cell("f", "k".into(), labels(), |f| run_with(vec![1.0 + f], false));
        assert_eq!(ok.outcome, Outcome::Converged);
        assert!((ok.error_vs_tighter.unwrap() - (1.0 - 1e-3)).abs() < 1e-12);
    }
}
