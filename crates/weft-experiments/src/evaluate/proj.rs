//! Experiment `proj`: the projection layers' cost and accuracy (Geng et al.).
//!
//! Inputs are network-like predictions of a sheet of Geng's size (3025 vertices at
//! standard size; 2969 in the paper): a uniform stretch, a smooth bump and deterministic
//! noise of about a tenth of an edge, one per example. Every SOCP method is scored against
//! a tight reference — Clarabel at tolerance 1e-10 followed by the active-set polish,
//! which certifies the unique optimum to round-off — by Geng's SqrtMSE and MaxDist (mm,
//! per example, then averaged). Time ratios divide by Clarabel at its default tolerance,
//! the off-the-shelf solver measured in the same run. The quasistatic layer solves a
//! different problem, so it reports its timings and edge energies, not an error against
//! the SOCP optimum.

use std::collections::HashMap;

use crate::error::Context;
use weft_proj::{
    ConicSolver, InextensibilityLayer, QuasistaticLayer, QuasistaticParams, RestShape, SocpSettings, ZeroLengthScaling,
    strain_summary,
};

use super::context::EvalContext;
use crate::records::{ExperimentOutput, Timing};
use crate::render::{View, error_png};
use weft_data::Size;
use weft_data::files::{Array, progress_bar, write_safetensors};

/// The inextensibility bound ε of every SOCP method (edges may stretch 10 %).
const EPSILON: f64 = 0.1;

/// A network-like prediction: stretch along x and y, a smooth bump and deterministic
/// noise (a linear congruential generator seeded per example) of about 0.2 % of the side.
fn prediction(rest: &weft_mesh::TriMesh, example: usize) -> Vec<f64> {
    let mut state: u64 = 0x5EED + example as u64;
    let mut noise = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.004
    };
    let (sx, sy) = (1.1 + 0.05 * example as f64, 1.05 + 0.02 * example as f64);
    rest.positions()
        .iter()
        .flat_map(|p| {
            let z = 0.05 * (4.0 * p.x + example as f64).sin() * (3.0 * p.y).cos();
            [sx * p.x + noise(), sy * p.y + noise(), z + noise()]
        })
        .collect()
}

fn socp(solver: ConicSolver, tolerance: f64, polish: bool) -> SocpSettings {
    SocpSettings {
        solver,
        tolerance,
        polish,
        ..SocpSettings::default()
    }
}

/// The sheet every method projects: its rest shape, the network-like predictions and
/// their reference projections.
struct Sheet<'a> {
    scene: &'a str,
    rest: &'a weft_mesh::TriMesh,
    shape: &'a RestShape,
    preds: &'a [Vec<f64>],
    reference: &'a [Vec<f64>],
    /// `predictions/proj/<scene>/` under the evaluation's directory.
    pred_dir: &'a std::path::Path,
}

impl Sheet<'_> {
    /// One SOCP method on every prediction: its records against the reference (the time
    /// ratio against Clarabel's, `gt_seconds`, set when `method` is Clarabel), its energies
    /// and predictions; returns the first example's projection and per-vertex error for the
    /// render, or `None` (a failure recorded) if a solve failed.
    fn score_method(
        &self,
        out: &mut ExperimentOutput,
        method: &str,
        settings: SocpSettings,
        bar: &indicatif::ProgressBar,
        gt_seconds: &mut Option<f64>,
    ) -> crate::Result<Option<(Vec<f64>, Vec<f64>)>> {
        let (scene, rest, preds, reference) = (self.scene, self.rest, self.preds, self.reference);
        let examples = preds.len();
        let pred_dir = self.pred_dir;
        let energy = |x: &[f64]| strain_summary(self.shape, x, 1.0);
        let layer = InextensibilityLayer::new(rest, EPSILON, settings)?;
        let mut solved = Vec::new();
        let mut seconds = 0.0;
        let mut worst_violation = f64::NEG_INFINITY;
        let mut failed = None;
        for p in preds {
            match layer.forward(p) {
                Ok((sol, report)) => {
                    seconds += report.time_seconds;
                    worst_violation = worst_violation.max(report.max_violation);
                    solved.push(sol);
                }
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
            bar.inc(1);
        }
        if let Some(e) = failed {
            out.failures.push(format!("proj/{scene}/{method}: {e}"));
            return Ok(None);
        }
        let per = seconds / examples as f64;
        if method == "clarabel" {
            *gt_seconds = Some(per);
        }
        let gt = gt_seconds.context("the Clarabel ground truth failed")?;
        let timing = Timing::new(per, gt);
        let (mut sqrt_mse, mut max_dist) = (0.0, 0.0);
        let mut truth = Vec::new();
        let mut flat = Vec::new();
        for (sol, r) in solved.iter().zip(reference) {
            let d: Vec<f64> = (0..rest.num_vertices())
                .map(|i| {
                    (0..3)
                        .map(|k| (sol.positions()[3 * i + k] - r[3 * i + k]).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .collect();
            sqrt_mse += 1e3 * (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
            max_dist += 1e3 * d.iter().fold(0.0f64, |m, x| m.max(*x));
            truth.extend_from_slice(r);
            flat.extend_from_slice(sol.positions());
        }
        let k = examples as f64;
        out.record(scene, method, "sqrt-mse", sqrt_mse / k, "mm", timing);
        out.record(scene, method, "max-dist", max_dist / k, "mm", timing);
        out.record(scene, method, "max-violation", worst_violation, "1", timing);
        out.record(scene, method, "forward-seconds", per, "s", timing);
        if method == "ipm" {
            // Geng et al. §4.1: "solving Equation 1 takes 3-4 seconds" (stored as 3.5).
            out.paper(3.5);
            let grad: Vec<f64> = (0..preds[0].len()).map(|i| (0.37 * i as f64).sin()).collect();
            let mut back = 0.0;
            for sol in &solved {
                back += layer.backward_with_report(sol, &grad)?.1.time_seconds;
            }
            out.record(
                scene,
                method,
                "backward-seconds",
                back / k,
                "s",
                Timing::new(back / k, gt),
            );
            // "computing ∂E/∂r̂ via η takes about 0.5 seconds".
            out.paper(0.5);
        }
        let e = energy(solved[0].positions())?;
        out.energy(scene, method, "stretching", e.stretching_energy, "J");
        out.energy(scene, method, "compression", e.compression_energy, "J");
        let v = rest.num_vertices();
        let mut meta = HashMap::new();
        meta.insert(
            "units".into(),
            "input (the prediction), positions (the projection) and ground_truth (the reference projection): \
                 [examples, vertices, 3] in metres"
                .into(),
        );
        meta.insert("epsilon".into(), EPSILON.to_string());
        write_safetensors(
            &pred_dir.join(format!("{method}.safetensors")),
            &[
                Array::f64("input", vec![examples, v, 3], &preds.concat()),
                Array::f64("positions", vec![examples, v, 3], &flat),
                Array::f64("ground_truth", vec![examples, v, 3], &truth),
            ],
            meta,
        )?;
        let errs: Vec<f64> = (0..v)
            .map(|i| {
                (0..3)
                    .map(|k| (solved[0].positions()[3 * i + k] - reference[0][3 * i + k]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .collect();
        Ok(Some((solved[0].positions().to_vec(), errs)))
    }
}

/// The quasistatic layer (Geng §5–6) at the paper's three global scalings: forward and
/// backward times against Clarabel's `gt` seconds, energies and the largest strain.
fn quasistatic_records(
    out: &mut ExperimentOutput,
    scene: &str,
    rest: &weft_mesh::TriMesh,
    shape: &RestShape,
    preds: &[Vec<f64>],
    gt: f64,
    bar: &indicatif::ProgressBar,
) -> crate::Result<()> {
    let examples = preds.len();
    let energy = |x: &[f64]| strain_summary(shape, x, 1.0);
    let quasi = QuasistaticLayer::new(rest, QuasistaticParams::default())?;
    for (tag, mu) in [("1", 1.0), ("0.1", 0.1), ("0.01", 0.01)] {
        let method = format!("quasistatic-mu-{tag}");
        let scaling = ZeroLengthScaling::Global(mu);
        let (mut fwd, mut back) = (0.0, 0.0);
        let mut first = None;
        for p in preds {
            let start = std::time::Instant::now();
            let (sol, _) = quasi
                .forward(p, &scaling)
                .with_context(|| format!("{method} forward"))?;
            fwd += start.elapsed().as_secs_f64();
            let grad: Vec<f64> = (0..p.len()).map(|i| (0.37 * i as f64).sin()).collect();
            let start = std::time::Instant::now();
            quasi
                .backward(&sol, &grad)
                .with_context(|| format!("{method} backward"))?;
            back += start.elapsed().as_secs_f64();
            first.get_or_insert_with(|| sol.positions().to_vec());
            bar.inc(1);
        }
        let k = examples as f64;
        out.record(
            scene,
            &method,
            "forward-seconds",
            fwd / k,
            "s",
            Timing::new(fwd / k, gt),
        );
        // Geng §6.1: "solving the quasistatic problem for r* takes about 0.07 seconds".
        out.paper(0.07);
        out.record(
            scene,
            &method,
            "backward-seconds",
            back / k,
            "s",
            Timing::new(back / k, gt),
        );
        // "computing ∂E/∂r̂ via η takes about 0.01 seconds".
        out.paper(0.01);
        let x = first.context("no example")?;
        let e = energy(&x)?;
        out.energy(scene, &method, "stretching", e.stretching_energy, "J");
        out.energy(scene, &method, "compression", e.compression_energy, "J");
        out.record(scene, &method, "max-strain", e.max_strain, "1", Timing::default());
    }
    Ok(())
}

pub fn run(ctx: &EvalContext) -> crate::Result<ExperimentOutput> {
    let mut out = ExperimentOutput::new("proj", ctx.size);
    let quick = ctx.size == Size::Quick;
    let (n, examples) = if quick { (17, 2) } else { (55, 4) };
    let scene = format!("sheet-{}", n * n);
    let rest = weft_mesh::generators::sheet(n, 1.0)?;
    let shape = RestShape::new(&rest)?;
    let preds: Vec<Vec<f64>> = (0..examples).map(|k| prediction(&rest, k)).collect();
    let methods: Vec<(&str, SocpSettings)> = vec![
        (
            "clarabel",
            SocpSettings {
                solver: ConicSolver::Clarabel,
                ..SocpSettings::default()
            },
        ),
        ("ipm", SocpSettings::default()),
        ("ipm-no-polish", socp(ConicSolver::ReducedIpm, 1e-8, false)),
        ("ipm-tol-1e-6", socp(ConicSolver::ReducedIpm, 1e-6, false)),
        ("ipm-tol-1e-4", socp(ConicSolver::ReducedIpm, 1e-4, false)),
        ("clarabel-no-polish", socp(ConicSolver::Clarabel, 1e-8, false)),
        ("clarabel-tol-1e-6", socp(ConicSolver::Clarabel, 1e-6, false)),
        ("clarabel-tol-1e-4", socp(ConicSolver::Clarabel, 1e-4, false)),
    ];
    let bar = progress_bar(
        ctx.quiet,
        ((methods.len() + 1 + 3) * examples) as u64,
        &format!("proj {scene}"),
        "solves",
    )?;
    let reference_layer = InextensibilityLayer::new(&rest, EPSILON, socp(ConicSolver::Clarabel, 1e-10, true))?;
    let mut reference = Vec::new();
    for p in &preds {
        let (sol, report) = reference_layer.forward(p).context("the reference SOCP solve failed")?;
        let polish = match report.polish_iterations {
            Some(k) => format!("polished in {k} Newton iteration(s)"),
            None => "polish rejected (the interior-point point is the reference)".into(),
        };
        out.notes.push(format!(
            "proj/{scene} example {}: reference {}, {polish}, KKT residual {:.1e}, max violation {:.1e}",
            reference.len(),
            report.status,
            report.kkt_residual,
            report.max_violation
        ));
        reference.push(sol.into_positions());
        bar.inc(1);
    }
    out.notes.push(format!(
        "proj/{scene}: {} vertices, {} edge constraints, ε = {EPSILON}, {examples} examples; SqrtMSE and MaxDist per \
         example against the reference, averaged over examples",
        rest.num_vertices(),
        shape.edges().len()
    ));
    let pred_dir = ctx.out.join("predictions").join("proj").join(&scene);
    let render_dir = ctx.out.join("renders").join("proj").join(&scene);
    std::fs::create_dir_all(&pred_dir)?;
    std::fs::create_dir_all(&render_dir)?;
    let energy = |x: &[f64]| strain_summary(&shape, x, 1.0);
    let e_in = energy(&preds[0])?;
    out.energy(&scene, "input", "stretching", e_in.stretching_energy, "J");
    out.energy(&scene, "input", "compression", e_in.compression_energy, "J");
    let e_ref = energy(&reference[0])?;
    out.energy(&scene, "reference", "stretching", e_ref.stretching_energy, "J");
    out.energy(&scene, "reference", "compression", e_ref.compression_energy, "J");

    let mut gt_seconds = None;
    let mut renders = Vec::new();
    let sheet = Sheet {
        scene: &scene,
        rest: &rest,
        shape: &shape,
        preds: &preds,
        reference: &reference,
        pred_dir: &pred_dir,
    };
    for (method, settings) in methods {
        if let Some((x, errs)) = sheet.score_method(&mut out, method, settings, &bar, &mut gt_seconds)? {
            renders.push((method, x, errs));
        }
    }
    let scale = renders
        .iter()
        .flat_map(|(_, _, e)| e.iter().copied())
        .fold(0.0f64, f64::max)
        .max(1e-9);
    for (method, x, errs) in renders {
        let rel = format!("renders/proj/{scene}/{method}.png");
        error_png(
            &ctx.out.join(&rel),
            &x,
            rest.faces(),
            &errs,
            scale,
            &format!("{scene} — {method} (example 0)"),
            View::TOP,
        )?;
        out.renders.push(rel);
    }

    let gt = gt_seconds.context("the Clarabel ground truth failed")?;
    quasistatic_records(&mut out, &scene, &rest, &shape, &preds, gt, &bar)?;
    bar.finish_and_clear();
    Ok(out)
}
