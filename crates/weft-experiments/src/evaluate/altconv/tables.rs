//! The altconv experiment's records and tables: the validation curves and the rate table,
//! every method scored on the known and unseen motions with the mean over seeds (and its
//! `-sd` record), the paper's Tables 1 and 2 beside ours, the per-step roll-out plots and
//! the error heat maps.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::Vector3;
use weft_data::{LimbDataset, LimbSequence};
use weft_nn::altconv::AltConvNet;
use weft_nn::graph::NormalizedAdjacency;

use super::linear_filter::LinearFilter;
use super::scoring::{Errors, Predictor, mean_distance_mm, peak, percentile, score, window, write_predictions};
use super::{SKINNING, WINDOWS};
use crate::error::Context;
use crate::evaluate::context::EvalContext;
use crate::paper::Table;
use crate::records::{ExperimentOutput, LinePlot, SeedFigure, Series, Timing, mean_and_spread, mean_sd};
use crate::render::{View, error_colors, error_png};

/// The validation curves' plot and, with several rates, the table of the rate chosen on
/// validation.
pub(super) fn training_tables(
    out: &mut ExperimentOutput,
    scene: &str,
    seed0: u64,
    rates: &[f64],
    validation_kind: &str,
    rate_rows: Vec<Vec<String>>,
    curves: Vec<Series>,
) {
    out.lines.push(LinePlot {
        name: if scene == "limb" {
            "validation-curves".into()
        } else {
            format!("{scene}-validation-curves")
        },
        title: format!("altconv / {scene}: validation error after each epoch ({validation_kind}), mean over seeds"),
        x_label: "epoch".into(),
        y_label: "validation vertex error (mm)".into(),
        log_y: true,
        series: curves,
    });
    if !rate_rows.is_empty() {
        let mut header = vec!["model".to_string()];
        header.extend(rates.iter().map(|lr| format!("lr {lr:e}")));
        header.push("chosen".into());
        out.tables.push(Table {
            title: format!("Alt-ConvLSTM learning rate chosen on validation (`{scene}`)"),
            caption: format!(
                "Best validation error ({validation_kind}, mm, the kept epoch) of seed {} at each learning rate; the \
                 other seeds train at the chosen one. The test split plays no part.",
                seed0
            ),
            header,
            rows: rate_rows,
        });
    }
}

/// What scoring one scene's methods shares.
pub(super) struct SceneScoring<'a> {
    pub ctx: &'a EvalContext,
    pub scene: &'a str,
    pub dataset: &'a LimbDataset,
    pub adj: &'a NormalizedAdjacency,
    /// Steps scored (the shortest sequence, at most the last window).
    pub horizon: usize,
    /// The roll-out windows up to the horizon.
    pub windows: &'a [usize],
    /// Ground-truth seconds per frame.
    pub gt: f64,
    /// Steps each model was trained on.
    pub train_steps: usize,
    /// The training seed of each model of a method, in its models' order.
    pub seeds: &'a [u64],
}

/// One method's scores on one split, one [`Errors`] per seed.
struct MethodRuns<'a> {
    scene: &'a str,
    method: &'a str,
    split: &'a str,
    runs: &'a [Errors],
    /// Each run's training seed; empty for skinning, which trains nothing.
    seeds: &'a [u64],
    timing: Timing,
}

impl MethodRuns<'_> {
    /// A figure over the seeds: one record per seed, their mean and, with several, the
    /// spread as the `-sd` record; skinning's single figure alone.
    fn record(&self, out: &mut ExperimentOutput, metric: &str, of: impl Fn(&Errors) -> f64, paper: Option<f64>) {
        if self.seeds.is_empty() {
            out.record(self.scene, self.method, metric, of(&self.runs[0]), "mm", self.timing);
            if let Some(p) = paper {
                out.paper(p);
            }
            out.split(self.split);
            return;
        }
        let per_seed: Vec<(u64, f64)> = self.seeds.iter().copied().zip(self.runs.iter().map(of)).collect();
        let figure = SeedFigure {
            scene: self.scene,
            method: self.method,
            metric,
            split: Some(self.split),
            unit: "mm",
            timing: self.timing,
            paper,
        };
        out.record_over_seeds(&figure, &per_seed);
    }

    /// The records of one method: single step, each roll-out window, the peak, and (past
    /// the skinning row, whose surfaces `skinned` holds) the distance to skinning.
    fn records(&self, out: &mut ExperimentOutput, s: &SceneScoring, skinned: &mut Option<Vec<Vec<f64>>>) {
        let (split, method, horizon) = (self.split, self.method, s.horizon);
        self.record(
            out,
            "error-mm-step1",
            |e: &Errors| window(&e.single, horizon).0,
            paper_value(split, method, true, 50).map(|p| p.0),
        );
        for &w in s.windows {
            self.record(
                out,
                &format!("error-mm-rollout{w}"),
                |e: &Errors| window(&e.rollout, w).0,
                paper_value(split, method, false, w).map(|p| p.0),
            );
        }
        self.record(
            out,
            &format!("error-mm-max-rollout{horizon}"),
            |e: &Errors| peak(&e.rollout, horizon),
            None,
        );
        // How far a model's roll-out strays from the skinned surface (mean per-vertex
        // distance over steps 1–H): a model whose error equals skinning's may be
        // skinning itself (it learned no secondary motion) or a different surface.
        match skinned {
            None => *skinned = Some(self.runs[0].surfaces.clone()),
            Some(skin) => self.record(
                out,
                &format!("distance-mm-to-skinning-rollout{horizon}"),
                |e: &Errors| mean_distance_mm(&e.surfaces, skin),
                None,
            ),
        }
    }

    /// The method's two table rows (single-step and roll-out): paper / ours per window.
    fn table_rows(&self, windows: &[usize]) -> Vec<Vec<String>> {
        let mut rows = Vec::new();
        for single_step in [true, false] {
            let mut row = vec![
                if single_step { "single-step" } else { "roll-out" }.to_string(),
                format!("`{}`", self.method),
            ];
            for &w in windows {
                let (m, sd) = mean_sd(self.runs.iter().map(|e| {
                    let steps = if single_step { &e.single } else { &e.rollout };
                    window(steps, w).0
                }));
                let paper = paper_value(self.split, self.method, single_step, w)
                    .map_or("—".to_string(), |(p, s)| format!("{p:.2}±{s:.2}"));
                row.push(format!("{paper} / {}", mean_and_spread(m, sd)));
            }
            rows.push(row);
        }
        rows
    }
}

/// A row of the tables: what predicts its surfaces.
pub(super) enum Method {
    Skinning,
    /// The linear filter, fitted and chosen on the training and validation splits.
    Filter(LinearFilter),
    /// A network variant's models, one per seed.
    Nets(Vec<AltConvNet>),
}

impl Method {
    /// One predictor per run: the seeds' models, or the one deterministic row.
    fn predictors(&self) -> Vec<Predictor<'_>> {
        match self {
            Method::Skinning => vec![Predictor::Skinning],
            Method::Filter(f) => vec![Predictor::Filter(f)],
            Method::Nets(nets) => nets.iter().map(Predictor::Net).collect(),
        }
    }
}

/// A method's last roll-out step on the first test sequence: (method, surface, errors).
pub(super) type Heat = (String, Vec<f64>, Vec<f64>);

/// Every method (skinning first; a network's models, one per seed) scored on the known and the
/// unseen motions: records, per-step plots, the paper's Tables 1 and 2 beside ours, and
/// the test predictions; returns the heat maps' data.
pub(super) fn score_splits(
    s: &SceneScoring,
    out: &mut ExperimentOutput,
    methods: &[(String, Method)],
) -> crate::Result<Vec<Heat>> {
    let (scene, horizon) = (s.scene, s.horizon);
    let mut tables_rows: HashMap<&str, Vec<Vec<String>>> = HashMap::new();
    let mut heat: Vec<Heat> = Vec::new();
    for (split, source) in [("known", "train"), ("test", "test")] {
        // Per-step roll-out errors: where each method drifts (mean and 99th percentile).
        let mut mean_series = Vec::new();
        let mut p99_series = Vec::new();
        let sequences: Vec<&LimbSequence> = s.dataset.split(source).collect();
        if sequences.is_empty() {
            out.failures
                .push(format!("altconv/{scene}/{split}: the dataset has no {source} sequence"));
            continue;
        }
        // The skinning row's roll-out surfaces (the first method scored).
        let mut skinned: Option<Vec<Vec<f64>>> = None;
        for (method, model) in methods {
            let runs: Vec<Errors> = model
                .predictors()
                .into_iter()
                .map(|p| score(p, s.adj, &sequences, horizon).with_context(|| format!("scoring {method}")))
                .collect::<crate::Result<Vec<_>>>()?;
            let e = &runs[0];
            let method_runs = MethodRuns {
                scene,
                method,
                split,
                runs: &runs,
                seeds: match model {
                    Method::Nets(_) => &s.seeds[..runs.len()],
                    // Deterministic: one run, no spread, as skinning.
                    Method::Skinning | Method::Filter(_) => &[],
                },
                timing: Timing::new(e.seconds_per_frame, s.gt),
            };
            method_runs.records(out, s, &mut skinned);
            let steps: Vec<f64> = (1..=horizon).map(|t| t as f64).collect();
            mean_series.push(Series {
                label: method.clone(),
                x: steps.clone(),
                y: e.rollout.iter().map(|v| mean_sd(v.iter().copied()).0).collect(),
            });
            p99_series.push(Series {
                label: method.clone(),
                x: steps,
                y: e.rollout.iter().map(|v| percentile(v, 0.99)).collect(),
            });
            tables_rows
                .entry(split)
                .or_default()
                .extend(method_runs.table_rows(s.windows));
            if split == "test" {
                write_predictions(s.ctx, method, s.dataset, source, horizon, &e.surfaces)?;
                if let Some((errs, x)) = e.last.clone() {
                    heat.push((method.clone(), x, errs));
                }
            }
        }
        for (stat, series) in [("mean", mean_series), ("p99", p99_series)] {
            out.lines.push(LinePlot {
                name: if scene == "limb" {
                    format!("rollout-{stat}-{split}")
                } else {
                    format!("{scene}-rollout-{stat}-{split}")
                },
                title: format!(
                    "altconv / {scene} ({split}): roll-out error at each step, {} over vertices and sequences",
                    if stat == "mean" { "mean" } else { "99th percentile" }
                ),
                x_label: format!("roll-out step (trained: 1–{})", s.train_steps),
                y_label: "vertex error (mm)".into(),
                log_y: false,
                series,
            });
        }
    }
    paper_tables(out, scene, s.windows, tables_rows);
    Ok(heat)
}

/// The paper's Tables 1 (known motions) and 2 (unseen ones) beside ours.
fn paper_tables(
    out: &mut ExperimentOutput,
    scene: &str,
    windows: &[usize],
    mut tables_rows: HashMap<&str, Vec<Vec<String>>>,
) {
    for (split, title, caption) in [
        (
            "known",
            "Alt-ConvLSTM Table 1 — future prediction error on known motions, paper / ours",
            "training sequences. Each cell: the paper's figure, mean±sd over vertices (Dynamic FAUST, 6890 \
             vertices) / ours, the mean error over steps 1–N and its sd over the seeds (skinning has none); column N = \
             steps 1–N. The paper's table starts at 20 steps.",
        ),
        (
            "test",
            "Alt-ConvLSTM Table 2 — generalisation error on unseen motions, paper / ours",
            "test sequences. Each cell: the paper's figure, mean±sd over vertices / ours, the mean error over steps \
             1–N and its sd over the seeds; column N = steps 1–N. The paper does not evaluate the ΔY baselines here.",
        ),
    ] {
        if let Some(rows) = tables_rows.remove(split) {
            let mut header = vec!["type".to_string(), "model".to_string()];
            header.extend(windows.iter().map(|w| format!("{w} steps")));
            out.tables.push(Table {
                title: format!("{title} (`{scene}`)"),
                caption: format!("Per-vertex error (mm), `{scene}` {caption}"),
                header,
                rows,
            });
        }
    }
}

/// The paper's Table 1 (known motions), columns 20–50 steps: (mean, sd) in mm.
fn paper_known(method: &str, single_step: bool) -> Option<[(f64, f64); 4]> {
    Some(match (method, single_step) {
        (SKINNING, _) => [(17.76, 2.67), (17.87, 2.67), (18.07, 2.66), (18.26, 2.69)],
        ("convlstm-cp-dy", true) => [(21.44, 20.67), (41.06, 32.54), (61.09, 42.91), (77.62, 49.00)],
        ("convlstm-np-dy", true) => [(21.21, 20.52), (40.53, 32.29), (60.36, 42.70), (76.76, 48.89)],
        ("convlstm-cp-y", true) => [(2.50, 0.38), (2.23, 0.45), (2.19, 0.48), (2.58, 0.52)],
        ("convlstm-np-y", true) => [(3.21, 0.43), (2.98, 0.46), (2.95, 0.50), (2.95, 0.51)],
        ("alt-convlstm", true) => [(0.97, 0.41), (1.09, 0.48), (1.21, 0.53), (1.30, 0.56)],
        ("convlstm-cp-dy", false) => [(22.04, 20.22), (41.33, 32.04), (61.00, 42.58), (77.20, 48.89)],
        ("convlstm-np-dy", false) => [(21.49, 20.18), (40.59, 31.83), (60.15, 42.34), (76.31, 48.71)],
        ("convlstm-cp-y", false) => [(13.94, 1.59), (14.89, 1.65), (16.62, 1.80), (18.87, 2.09)],
        ("convlstm-np-y", false) => [(13.30, 1.62), (14.21, 1.82), (15.73, 2.27), (17.34, 2.72)],
        ("alt-convlstm", false) => [(3.38, 2.08), (4.94, 2.98), (6.52, 3.70), (7.92, 4.11)],
        _ => return None,
    })
}

/// The paper's Table 2 (unseen motions), columns 10–50 steps: (mean, sd) in mm. The
/// paper evaluates only the `-Y` baselines there.
fn paper_test(method: &str, single_step: bool) -> Option<[(f64, f64); 5]> {
    Some(match (method, single_step) {
        (SKINNING, _) => [
            (19.40, 3.17),
            (19.42, 3.20),
            (19.51, 3.13),
            (19.64, 2.97),
            (19.86, 2.87),
        ],
        ("convlstm-cp-y", true) => [(4.13, 0.69), (2.66, 0.51), (2.31, 0.48), (2.22, 0.46), (2.69, 0.64)],
        ("convlstm-np-y", true) => [(4.70, 0.76), (3.45, 0.62), (3.12, 0.57), (3.03, 0.54), (3.05, 0.54)],
        ("alt-convlstm", true) => [(0.97, 0.67), (1.00, 0.55), (1.08, 0.52), (1.17, 0.48), (1.29, 0.51)],
        ("convlstm-cp-y", false) => [
            (14.45, 2.17),
            (15.24, 2.32),
            (16.10, 2.33),
            (17.67, 2.33),
            (20.07, 2.81),
        ],
        ("convlstm-np-y", false) => [
            (14.06, 2.17),
            (14.51, 2.55),
            (15.27, 2.90),
            (16.60, 3.17),
            (18.18, 3.40),
        ],
        ("alt-convlstm", false) => [(2.32, 1.71), (3.70, 2.51), (5.18, 3.03), (6.64, 3.24), (8.14, 3.28)],
        _ => return None,
    })
}

/// The paper's (mean, sd) for `window` steps, or `None` where it prints none.
pub(super) fn paper_value(split: &str, method: &str, single_step: bool, window: usize) -> Option<(f64, f64)> {
    match split {
        "known" => paper_known(method, single_step)
            .and_then(|row| [20, 30, 40, 50].iter().position(|&w| w == window).map(|k| row[k])),
        _ => paper_test(method, single_step).and_then(|row| WINDOWS.iter().position(|&w| w == window).map(|k| row[k])),
    }
}

/// Error heat maps of the last roll-out step on the first test sequence: a PNG per method
/// in the report and a PLY with per-vertex colours beside it, all on the skinning row's
/// largest error as the common scale (the floor every model should beat).
pub(super) fn render_heat_maps(
    ctx: &EvalContext,
    out: &mut ExperimentOutput,
    dataset: &LimbDataset,
    heat: &[(String, Vec<f64>, Vec<f64>)],
    horizon: usize,
) -> crate::Result<()> {
    let scale = heat
        .iter()
        .find(|(m, _, _)| m == SKINNING)
        .map(|(_, _, e)| e.iter().copied().fold(0.0f64, f64::max))
        .unwrap_or(0.0)
        .max(1e-6);
    let scene = dataset.name.as_str();
    let dir = Path::new("renders").join("altconv").join(scene);
    std::fs::create_dir_all(ctx.out.join(&dir))?;
    for (method, x, errs) in heat {
        let png = dir.join(format!("{method}.png"));
        error_png(
            &ctx.out.join(&png),
            x,
            dataset.rest.faces(),
            errs,
            scale,
            &format!("{scene} — {method}, roll-out step {horizon} (test)"),
            View::BEAM,
        )?;
        out.renders.push(png.display().to_string());
        let points: Vec<Vector3<f64>> = x.chunks_exact(3).map(|p| Vector3::new(p[0], p[1], p[2])).collect();
        weft_mesh::io::write_ply(
            &ctx.out.join(dir.join(format!("{method}.ply"))),
            &points,
            dataset.rest.faces(),
            Some(&error_colors(errs, scale)),
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluate::altconv::SKINNING;

    #[test]
    fn paper_values_are_read_from_the_right_table_and_column() {
        // Table 1's 50-step roll-out: 7.92 for Alt-ConvLSTM, 17.34 for the best vanilla model.
        assert_eq!(paper_value("known", "alt-convlstm", false, 50), Some((7.92, 4.11)));
        assert_eq!(paper_value("known", "convlstm-np-y", false, 50), Some((17.34, 2.72)));
        // Table 1 starts at 20 steps; Table 2 at 10, without the ΔY baselines.
        assert_eq!(paper_value("known", "alt-convlstm", true, 10), None);
        assert_eq!(paper_value("test", "alt-convlstm", true, 10), Some((0.97, 0.67)));
        assert_eq!(paper_value("test", "convlstm-cp-dy", false, 50), None);
        assert_eq!(paper_value("test", SKINNING, false, 30), Some((19.51, 3.13)));
        assert_eq!(paper_value("known", SKINNING, true, 20), Some((17.76, 2.67)));
    }
}
