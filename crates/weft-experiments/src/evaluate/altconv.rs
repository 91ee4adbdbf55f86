//! The `altconv` experiment (Alt-ConvLSTM, seed 001 §5.2, Tables 1–2) on the soft-tissue
//! datasets `limb` and `limb-jiggle`: Alt-ConvLSTM, the four graph ConvLSTM baselines and
//! the skinning-only row, each network trained on the dataset's training sequences with
//! three seeds under one recipe per dataset ([`training_config`]; the learning rate chosen
//! on validation where [`learning_rates`] offers several) and scored on the training motions
//! (`known`) and on unseen ones (`test`).
//!
//! Metrics (per-vertex Euclidean error, Eq. 12, in mm; docs/RESULTS.md):
//! - `error-mm-step1`: single-step, every step starting from the true previous surface,
//!   averaged over steps 1–H (H = 50 where the sequences are long enough);
//! - `error-mm-rollout{N}`: a roll-out from the initial surface on the model's own
//!   predictions, averaged over its steps 1–N.
//!
//! The paper's columns "N steps" are read the same way: its 20-step known-motion column is
//! the training loss, the mean over the 20 teacher-forced training steps.

use std::collections::HashMap;
use std::path::Path;

use crate::error::Context;
use nalgebra::Vector3;
use weft_data::{LimbDataset, LimbSequence};
use weft_nn::altconv::{AltConvNet, AltConvTrainingSettings, Recipe, Variant, score_sequence};
use weft_nn::graph::NormalizedAdjacency;

use super::context::EvalContext;
use crate::paper::Table;
use crate::records::{ExperimentOutput, LinePlot, Series, Timing, mean_and_spread, mean_sd};
use crate::render::{View, error_colors, error_png};
use weft_data::Size;

/// The soft-tissue datasets the experiment runs on: `limb`, whose tissue barely leaves the
/// skinned surface, and `limb-jiggle`, whose secondary motion is the thing to learn
/// (docs/ALTCONV.md).
const SCENES: [&str; 2] = ["limb", "limb-jiggle"];

/// Seeds per model: one at quick size (CI), three otherwise.
fn seeds(size: Size) -> Vec<u64> {
    match size {
        Size::Quick => vec![0],
        _ => vec![0, 1, 2],
    }
}
const SKINNING: &str = "skinning";
/// Roll-out windows of the tables (steps).
const WINDOWS: [usize; 5] = [10, 20, 30, 40, 50];
/// Frames per quick sequence: enough for the 10-step window.
const QUICK_FRAMES: usize = 12;

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
fn paper_value(split: &str, method: &str, single_step: bool, window: usize) -> Option<(f64, f64)> {
    match split {
        "known" => paper_known(method, single_step)
            .and_then(|row| [20, 30, 40, 50].iter().position(|&w| w == window).map(|k| row[k])),
        _ => paper_test(method, single_step).and_then(|row| WINDOWS.iter().position(|&w| w == window).map(|k| row[k])),
    }
}

/// The training configuration of every model on the dataset `scene` at `size`, the same
/// for every model as the paper compares them, at the first of [`learning_rates`] (the
/// experiment chooses among them on validation).
///
/// `limb` keeps the short teacher-forced recipe it was published with (its models stay
/// cached). `limb-jiggle`, where the claim is decided, trains on the evaluated horizon: a
/// curriculum from 10 to 50 steps over the first 8 epochs, scheduled sampling rising from
/// epoch 3 to pure roll-out training at epoch 15, gradients clipped to norm 1, and the
/// kept epoch chosen by the 50-step validation roll-out (docs/ALTCONV.md, *The claim decided*).
pub fn training_config(size: Size, scene: &str, variant: Variant) -> AltConvTrainingSettings {
    let mut c = AltConvTrainingSettings::new(variant);
    let jiggle = scene != "limb";
    match size {
        Size::Quick => {
            c.hidden = vec![8, 16, 8];
            c.steps = 6;
            c.epochs = 2;
            if jiggle {
                c.recipe = Recipe {
                    sampling_max: 0.5,
                    sampling_epochs: [0, 2],
                    validation_rollout: true,
                    ..Recipe::default()
                };
            }
        }
        _ if jiggle => {
            c.steps = 50;
            c.epochs = JIGGLE_EPOCHS;
            c.batch = 1;
            c.schedule.clip_grad_norm = Some(1.0);
            c.recipe = Recipe {
                sampling_max: 1.0,
                sampling_epochs: [3, 15],
                curriculum_start: 10,
                curriculum_epochs: 8,
                validation_rollout: true,
            };
        }
        _ => {
            c.epochs = STANDARD_EPOCHS;
            // One sequence per Adam step: the few steps a standard run affords.
            c.batch = 1;
        }
    }
    c.adam.learning_rate = learning_rates(size, scene)[0];
    c
}

/// The learning rates tried for every model on `scene` (the paper tries 10⁻¹, 10⁻² and
/// 10⁻³ for its baselines and keeps the best): each is trained with the first seed and the
/// one with the best validation score is kept for the other seeds.
pub fn learning_rates(size: Size, scene: &str) -> Vec<f64> {
    match (size, scene) {
        (Size::Quick, _) | (_, "limb") => vec![1e-3],
        _ => vec![1e-3, 1e-2],
    }
}

/// Epochs of the standard evaluation on `limb` (the paper trains 1000; the cost of one is
/// in docs/ALTCONV.md, *Training length*).
const STANDARD_EPOCHS: usize = 12;
/// Epochs on `limb-jiggle`: each trains the full 50-step window once the curriculum ends;
/// 80 is where every row's validation curve has flattened (docs/ALTCONV.md).
const JIGGLE_EPOCHS: usize = 80;

/// Removes a model directory trained under another configuration than `config` (or
/// whose configuration cannot be read), so that it is retrained rather than refused. A
/// model trained for fewer epochs under the same configuration is kept: the trainer
/// continues it to `config.epochs`, as a straight run would have gone (a larger epoch
/// budget costs only the new epochs).
fn discard_if_stale(dir: &Path, config: &AltConvTrainingSettings) -> crate::Result<()> {
    let path = dir.join("config.json");
    if !path.exists() {
        return Ok(());
    }
    let stored: Option<AltConvTrainingSettings> = std::fs::read_to_string(&path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .filter(|s: &AltConvTrainingSettings| s.epochs <= config.epochs)
        .map(|s| AltConvTrainingSettings {
            epochs: config.epochs,
            ..s
        });
    if stored.as_ref() != Some(config) {
        eprintln!(
            "altconv: {} was trained under another configuration; retraining it",
            dir.display()
        );
        std::fs::remove_dir_all(dir).with_context(|| format!("removing {}", dir.display()))?;
    }
    Ok(())
}

/// Per-step pooled vertex errors (mm) of one method on one split: `[step][sample]`.
struct Errors {
    single: Vec<Vec<f64>>,
    rollout: Vec<Vec<f64>>,
    /// Roll-out wall time per step and sequence (s).
    seconds_per_frame: f64,
    /// The last roll-out step's vertex errors (m) and surface of the split's first
    /// sequence, for the heat map.
    last: Option<(Vec<f64>, Vec<f64>)>,
    /// Every sequence's roll-out surfaces, flattened `[steps, V, 3]` each.
    surfaces: Vec<Vec<f64>>,
}

/// The `q` quantile of `samples` (nearest rank).
fn percentile(samples: &[f64], q: f64) -> f64 {
    let mut v = samples.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(((q * v.len() as f64).ceil() as usize).saturating_sub(1))
        .copied()
        .unwrap_or(0.0)
}

/// Steps 1..=n pooled.
fn window(steps: &[Vec<f64>], n: usize) -> (f64, f64) {
    mean_sd(steps[..n].iter().flatten().copied())
}

/// The mean per-vertex distance (mm) between two sets of roll-outs (each sequence's
/// surfaces flattened `[steps, V, 3]`, metres).
fn mean_distance_mm(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let d = a.iter().zip(b).flat_map(|(a, b)| {
        a.chunks_exact(3)
            .zip(b.chunks_exact(3))
            .map(|(p, q)| 1e3 * ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
    });
    mean_sd(d).0
}

/// The largest per-vertex error over the first `n` steps (mm).
fn peak(steps: &[Vec<f64>], n: usize) -> f64 {
    steps[..n].iter().flatten().copied().fold(0.0, f64::max)
}

/// Scores `net` (or skinning, when `None`) on `sequences` over `horizon` steps.
fn score(
    net: Option<&AltConvNet>,
    adj: &NormalizedAdjacency,
    sequences: &[&LimbSequence],
    horizon: usize,
) -> crate::Result<Errors> {
    let mut single = vec![Vec::new(); horizon];
    let mut rollout = vec![Vec::new(); horizon];
    let mut seconds = 0.0;
    let mut last = None;
    let mut surfaces = Vec::with_capacity(sequences.len());
    for (k, s) in sequences.iter().enumerate() {
        let e = score_sequence(net, adj, s, horizon)?;
        seconds += e.rollout_seconds;
        for t in 0..horizon {
            single[t].extend(e.single[t].iter().map(|e| 1e3 * e));
            rollout[t].extend(e.rollout[t].iter().map(|e| 1e3 * e));
        }
        if k == 0 {
            last = Some((e.rollout[horizon - 1].clone(), e.rollout_surfaces[horizon - 1].clone()));
        }
        surfaces.push(e.rollout_surfaces.concat());
    }
    Ok(Errors {
        single,
        rollout,
        seconds_per_frame: seconds / (horizon * sequences.len().max(1)) as f64,
        last,
        surfaces,
    })
}

pub fn run(ctx: &EvalContext) -> crate::Result<ExperimentOutput> {
    let mut out = ExperimentOutput::new("altconv", ctx.size);
    let seeds = seeds(ctx.size);
    out.seeds = seeds.len();
    for scene in SCENES {
        run_scene(ctx, &mut out, scene, &seeds).with_context(|| format!("altconv on {scene}"))?;
    }
    Ok(out)
}

/// Every model with every seed on the dataset `scene`, scored beside skinning: each record
/// is the mean over the seeds, its `-sd` twin their spread; the seed with the best
/// validation score draws the plots, predictions and renders.
fn run_scene(ctx: &EvalContext, out: &mut ExperimentOutput, scene: &str, seeds: &[u64]) -> crate::Result<()> {
    let root = ctx.out.join("altconv");
    // `limb` keeps the directory it had before there were two datasets.
    let base = if scene == "limb" {
        root.clone()
    } else {
        root.join(scene)
    };
    let data = base.join("data");
    let frames = (ctx.size == Size::Quick).then_some(QUICK_FRAMES);
    let stopped = super::context::generate_dataset_frames(ctx, scene, &data, frames).context("soft-tissue dataset")?;
    out.failures.extend(stopped);
    let gt = super::context::ground_truth_seconds(&data)?;
    let dataset = LimbDataset::load(&data)?;
    let adj = NormalizedAdjacency::new(&dataset.rest)?;
    let device = weft_nn::Device::Cpu;
    // Per variant, its models (one per seed) with the best validation score first.
    let mut trained_models: Vec<(Variant, Vec<(f64, std::path::PathBuf)>)> = Vec::new();
    let rates = learning_rates(ctx.size, scene);
    let mut rate_rows = Vec::new();
    let mut curves = Vec::new();
    for variant in Variant::ALL {
        let variant_dir = base.join("models").join(variant.name());
        let train = |seed: u64, lr: f64| -> crate::Result<(weft_nn::trainer::TrainingState, std::path::PathBuf)> {
            let mut config = AltConvTrainingSettings {
                seed,
                ..training_config(ctx.size, scene, variant)
            };
            config.adam.learning_rate = lr;
            // One rate keeps the layout the models had before there was a choice.
            let model_dir = if rates.len() > 1 {
                variant_dir.join(format!("lr-{lr:e}")).join(format!("seed-{seed}"))
            } else {
                variant_dir.join(format!("seed-{seed}"))
            };
            discard_if_stale(&model_dir, &config)?;
            let label = format!("altconv/{scene}/{}/lr-{lr:e}/seed-{seed}", variant.name());
            let mut progress = crate::progress::TrainProgress::new(ctx.quiet, &label)?;
            let trained = weft_nn::altconv::train_model(&model_dir, &dataset, &config, &mut progress)
                .with_context(|| format!("training {label}"))?;
            Ok((trained.state, model_dir))
        };
        // The rate: the first seed at each, the best validation score (a single rate is
        // simply trained).
        let mut runs = Vec::new();
        let mut by_rate = Vec::new();
        for &lr in &rates {
            let run = train(seeds[0], lr)?;
            by_rate.push((lr, run.0.best_validation));
            runs.push((lr, run));
        }
        let chosen = by_rate
            .iter()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|r| r.0)
            .context("no learning rate")?;
        let mut runs: Vec<_> = runs.into_iter().filter(|r| r.0 == chosen).map(|r| r.1).collect();
        for &seed in &seeds[1..] {
            runs.push(train(seed, chosen)?);
        }
        if rates.len() > 1 {
            let mut row = vec![format!("`{}`", variant.name())];
            row.extend(by_rate.iter().map(|(_, v)| format!("{:.2}", 1e3 * v)));
            row.push(format!("{chosen:e}"));
            rate_rows.push(row);
        }
        let mut config = training_config(ctx.size, scene, variant);
        config.adam.learning_rate = chosen;
        let config_path = base.join("configs").join(format!("{}.json", variant.name()));
        std::fs::create_dir_all(config_path.parent().context("config directory")?)?;
        std::fs::write(&config_path, serde_json::to_string_pretty(&config)?)?;
        // Wall time per training sequence pass (forward, backward, Adam), from each run's
        // own record: the fused kernels unless the configuration asks for autograd. The
        // median epoch, so a paused or shared epoch does not move it.
        let seconds: Vec<f64> = runs
            .iter()
            .map(|(state, _)| state.median_epoch_seconds() / dataset.split("train").count().max(1) as f64)
            .collect();
        out.record(
            scene,
            variant.name(),
            "training-seconds-per-example",
            mean_sd(seconds.iter().copied()).0,
            "s",
            Timing::default(),
        );
        set_split(out, "train");
        // The validation curve, mean over the seeds (mm).
        let epochs = runs.iter().map(|(s, _)| s.history.len()).min().unwrap_or(0);
        curves.push(Series {
            label: variant.name().into(),
            x: (1..=epochs).map(|e| e as f64).collect(),
            y: (0..epochs)
                .map(|e| 1e3 * mean_sd(runs.iter().map(|(s, _)| s.history[e].validation)).0)
                .collect(),
        });
        let mut models: Vec<(f64, std::path::PathBuf)> = runs
            .into_iter()
            .map(|(state, dir)| (state.best_validation, dir))
            .collect();
        models.sort_by(|a, b| a.0.total_cmp(&b.0));
        trained_models.push((variant, models));
    }
    let recipe = training_config(ctx.size, scene, Variant::Alt);
    let validation_kind = if recipe.recipe.validation_rollout {
        format!("{}-step roll-out", recipe.steps)
    } else {
        format!("{}-step teacher-forced", recipe.steps)
    };
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
                seeds[0]
            ),
            header,
            rows: rate_rows,
        });
    }
    let longest_common = dataset.sequences.iter().map(|s| s.skinned.len() - 1).min().unwrap_or(0);
    let horizon = longest_common.min(*WINDOWS.last().unwrap_or(&50));
    crate::error::ensure!(horizon >= 1, "the limb sequences hold no step");
    let windows: Vec<usize> = WINDOWS.iter().copied().filter(|&w| w <= horizon).collect();
    let train_steps = recipe.steps;
    out.notes.push(format!(
        "altconv/{scene}: {} seed(s) per model (each figure their mean, its `-sd` record their spread; plots, \
         predictions and renders from the seed with the best validation score); {} surface vertices (the limb's boundary, metres, scored in mm); models trained on \
         the first {train_steps} steps of each `train` sequence ({} epochs, batch {}, recipe {}, learning rate from {:?} \
         chosen on validation, the kept epoch the best {validation_kind} validation score); `known` = the training \
         sequences, `test` = unseen ones; single-step and roll-out errors over steps 1–{horizon}; roll-out time per \
         frame of AltConvRuntime on this machine against the Neo-Hookean ground truth's time per stored frame from the \
         dataset's timing.json",
        seeds.len(),
        dataset.rest.num_vertices(),
        recipe.epochs,
        recipe.batch,
        serde_json::to_string(&recipe.recipe)?,
        rates,
    ));
    // Skinning has no seeds: one run, no spread.
    let mut methods: Vec<(String, Vec<AltConvNet>)> = vec![(SKINNING.into(), Vec::new())];
    for (variant, models) in &trained_models {
        let nets = models
            .iter()
            .map(|(_, dir)| Ok(weft_nn::altconv::load_model(dir, &device)?.2))
            .collect::<crate::Result<Vec<_>>>()?;
        methods.push((variant.name().into(), nets));
    }
    let mut tables_rows: HashMap<&str, Vec<Vec<String>>> = HashMap::new();
    let mut heat: Vec<(String, Vec<f64>, Vec<f64>)> = Vec::new();
    for (split, source) in [("known", "train"), ("test", "test")] {
        // Per-step roll-out errors: where each method drifts (mean and 99th percentile).
        let mut mean_series = Vec::new();
        let mut p99_series = Vec::new();
        let sequences: Vec<&LimbSequence> = dataset.split(source).collect();
        if sequences.is_empty() {
            out.failures
                .push(format!("altconv/{scene}/{split}: the dataset has no {source} sequence"));
            continue;
        }
        // The skinning row's roll-out surfaces (the first method scored).
        let mut skinned: Option<Vec<Vec<f64>>> = None;
        for (method, nets) in &methods {
            let runs: Vec<Errors> = if nets.is_empty() {
                vec![score(None, &adj, &sequences, horizon).with_context(|| format!("scoring {method}"))?]
            } else {
                nets.iter()
                    .map(|n| score(Some(n), &adj, &sequences, horizon).with_context(|| format!("scoring {method}")))
                    .collect::<crate::Result<Vec<_>>>()?
            };
            let e = &runs[0];
            let timing = Timing::new(e.seconds_per_frame, gt);
            // A figure over the seeds: the mean, and the spread as the `-sd` record.
            let record = |out: &mut ExperimentOutput, metric: String, of: &dyn Fn(&Errors) -> f64, paper| {
                let (m, sd) = mean_sd(runs.iter().map(of));
                out.record(scene, method, &metric, m, "mm", timing);
                if let Some(p) = paper {
                    out.paper(p);
                }
                set_split(out, split);
                out.record(scene, method, &format!("{metric}-sd"), sd, "mm", Timing::default());
                set_split(out, split);
            };
            record(
                out,
                "error-mm-step1".into(),
                &|e: &Errors| window(&e.single, horizon).0,
                paper_value(split, method, true, 50).map(|p| p.0),
            );
            for &w in &windows {
                record(
                    out,
                    format!("error-mm-rollout{w}"),
                    &|e: &Errors| window(&e.rollout, w).0,
                    paper_value(split, method, false, w).map(|p| p.0),
                );
            }
            record(
                out,
                format!("error-mm-max-rollout{horizon}"),
                &|e: &Errors| peak(&e.rollout, horizon),
                None,
            );
            // How far a model's roll-out strays from the skinned surface (mean per-vertex
            // distance over steps 1–H): a model whose error equals skinning's may be
            // skinning itself (it learned no secondary motion) or a different surface.
            match &skinned {
                None => skinned = Some(e.surfaces.clone()),
                Some(skin) => record(
                    out,
                    format!("distance-mm-to-skinning-rollout{horizon}"),
                    &|e: &Errors| mean_distance_mm(&e.surfaces, skin),
                    None,
                ),
            }
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
            let rows = tables_rows.entry(split).or_default();
            for single_step in [true, false] {
                let mut row = vec![
                    if single_step { "single-step" } else { "roll-out" }.to_string(),
                    format!("`{method}`"),
                ];
                for &w in &windows {
                    let (m, sd) = mean_sd(runs.iter().map(|e| {
                        let steps = if single_step { &e.single } else { &e.rollout };
                        window(steps, w).0
                    }));
                    let paper = paper_value(split, method, single_step, w)
                        .map_or("—".to_string(), |(p, s)| format!("{p:.2}±{s:.2}"));
                    row.push(format!("{paper} / {}", mean_and_spread(m, sd)));
                }
                rows.push(row);
            }
            if split == "test" {
                write_predictions(ctx, method, &dataset, source, horizon, &e.surfaces)?;
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
                x_label: format!("roll-out step (trained: 1–{train_steps})"),
                y_label: "vertex error (mm)".into(),
                log_y: false,
                series,
            });
        }
    }
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
    render_heat_maps(ctx, out, &dataset, &heat, horizon)?;
    Ok(())
}

/// Writes `predictions/altconv/limb/<method>.safetensors`: the roll-outs of the `source`
/// split's sequences beside their ground truth, steps 1..=`horizon`.
fn write_predictions(
    ctx: &EvalContext,
    method: &str,
    dataset: &LimbDataset,
    source: &str,
    horizon: usize,
    surfaces: &[Vec<f64>],
) -> crate::Result<()> {
    let dir = ctx.out.join("predictions").join("altconv").join(&dataset.name);
    std::fs::create_dir_all(&dir)?;
    let sequences: Vec<_> = dataset.split(source).collect();
    let truth: Vec<f64> = sequences
        .iter()
        .flat_map(|s| s.simulated[1..=horizon].iter().flatten().copied())
        .collect();
    let index: Vec<i64> = sequences.iter().map(|s| s.index as i64).collect();
    let shape = vec![sequences.len(), horizon, dataset.rest.num_vertices(), 3];
    let mut meta = HashMap::new();
    meta.insert(
        "units".into(),
        format!(
            "positions (the roll-out from each sequence's initial surface) and ground_truth [sequences, steps 1..={horizon}, \
             vertices, 3] in metres, the `{source}` sequences of the limb dataset; sequence_index [sequences]"
        ),
    );
    Ok(weft_data::files::write_safetensors(
        &dir.join(format!("{method}.safetensors")),
        &[
            weft_data::files::Array::f64("positions", shape.clone(), &surfaces.concat()),
            weft_data::files::Array::f64("ground_truth", shape, &truth),
            weft_data::files::Array::i64("sequence_index", &index),
        ],
        meta,
    )?)
}

fn set_split(out: &mut ExperimentOutput, split: &str) {
    if let Some(r) = out.records.last_mut() {
        r.split = Some(split.into());
    }
}

/// Error heat maps of the last roll-out step on the first test sequence: a PNG per method
/// in the report and a PLY with per-vertex colours beside it, all on the skinning row's
/// largest error as the common scale (the floor every model should beat).
fn render_heat_maps(
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

/// Scores the model in `model_dir` (`cargo xtask train altconv`) on the `split` sequences
/// of the `limb` dataset in `data_dir`, beside skinning alone, with the evaluation's
/// metrics: `error-mm-step1` and `error-mm-rollout{10,…,50}` (windows up to the shortest
/// sequence), and each method's predictions under `ctx.out/predictions/altconv/limb/`.
pub fn score_model(
    ctx: &EvalContext,
    model_dir: &Path,
    data_dir: &Path,
    split: &str,
) -> crate::Result<ExperimentOutput> {
    let dataset = LimbDataset::load(data_dir)?;
    let (config, _, net) = weft_nn::altconv::load_model(model_dir, &weft_nn::Device::Cpu)
        .with_context(|| format!("loading the model in {}", model_dir.display()))?;
    let adj = NormalizedAdjacency::new(&dataset.rest)?;
    let sequences: Vec<&LimbSequence> = dataset.split(split).collect();
    crate::error::ensure!(!sequences.is_empty(), "{} has no {split} sequence", data_dir.display());
    let horizon = sequences
        .iter()
        .map(|s| s.skinned.len() - 1)
        .min()
        .unwrap_or(0)
        .min(*WINDOWS.last().unwrap_or(&50));
    crate::error::ensure!(horizon >= 1, "the {split} sequences hold no step");
    let gt = super::context::ground_truth_seconds(data_dir).ok();
    let mut out = ExperimentOutput::new("altconv", ctx.size);
    out.notes.push(format!(
        "altconv score: {} on the {split} sequences of {} ({} of them, steps 1–{horizon}), beside skinning",
        model_dir.display(),
        data_dir.display(),
        sequences.len()
    ));
    for (method, model) in [(SKINNING, None), (config.variant.name(), Some(&net))] {
        let e = score(model, &adj, &sequences, horizon).with_context(|| format!("scoring {method}"))?;
        let timing = Timing {
            seconds_per_frame: Some(e.seconds_per_frame),
            ground_truth_seconds_per_frame: gt,
        };
        out.record(
            &dataset.name,
            method,
            "error-mm-step1",
            window(&e.single, horizon).0,
            "mm",
            timing,
        );
        set_split(&mut out, split);
        for w in WINDOWS.into_iter().filter(|&w| w <= horizon) {
            out.record(
                &dataset.name,
                method,
                &format!("error-mm-rollout{w}"),
                window(&e.rollout, w).0,
                "mm",
                timing,
            );
            set_split(&mut out, split);
        }
        out.record(
            &dataset.name,
            method,
            &format!("error-mm-max-rollout{horizon}"),
            peak(&e.rollout, horizon),
            "mm",
            timing,
        );
        set_split(&mut out, split);
        write_predictions(ctx, method, &dataset, split, horizon, &e.surfaces)?;
    }
    Ok(out)
}

/// What `cargo xtask train altconv` reports of a model it trained: its roll-out error over
/// up to 50 steps of the dataset's validation sequences beside skinning alone, printed and
/// written to `scores.json` in the model directory. Validation, not test: a run made to
/// choose a recipe must not see the figures the claim is decided on (the evaluation reads
/// the test split once).
pub fn summarize_trained(
    out: &Path,
    dataset: &LimbDataset,
    trained: &weft_nn::altconv::TrainedAltConv,
) -> crate::Result<()> {
    // Where the model stands on held-out motions: the roll-out against skinning alone.
    let validation: Vec<_> = dataset.split("validation").collect();
    if let Some(frames) = validation.iter().map(|s| s.skinned.len()).min() {
        let horizon = (frames - 1).min(50);
        let mut scores = serde_json::Map::new();
        for (name, model) in [("skinning", None), (trained.net.variant().name(), Some(&trained.net))] {
            let mut sum = (0.0, 0usize);
            for s in &validation {
                let e = weft_nn::altconv::score_sequence(model, &trained.adj, s, horizon)?;
                sum.0 += e.rollout.iter().flatten().sum::<f64>();
                sum.1 += e.rollout.iter().map(Vec::len).sum::<usize>();
            }
            let mm = 1e3 * sum.0 / sum.1.max(1) as f64;
            eprintln!(
                "altconv/{}: {name} roll-out error over steps 1-{horizon} of the validation sequences: {mm:.3} mm",
                trained.net.variant().name()
            );
            scores.insert(name.to_string(), serde_json::json!(mm));
        }
        weft_data::files::write_text(
            &out.join("scores.json"),
            &serde_json::to_string_pretty(&serde_json::json!({ "steps": horizon, "validation_rollout_mm": scores }))?,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn a_model_trained_under_another_configuration_is_discarded() {
        let dir = std::env::temp_dir().join(format!("weft-altconv-stale-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let config = training_config(Size::Quick, "limb", Variant::Alt);
        std::fs::write(dir.join("config.json"), serde_json::to_string(&config).unwrap()).unwrap();
        discard_if_stale(&dir, &config).unwrap();
        assert!(dir.exists(), "the same configuration keeps the model");
        // More epochs continue the model; fewer, or any other change, retrain it.
        let mut longer = config.clone();
        longer.epochs += 1;
        discard_if_stale(&dir, &longer).unwrap();
        assert!(dir.exists(), "a longer budget keeps the model to continue it");
        let mut shorter = config.clone();
        shorter.epochs -= 1;
        discard_if_stale(&dir, &shorter).unwrap();
        assert!(!dir.exists(), "a shorter budget discards it");
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("config.json"), serde_json::to_string(&config).unwrap()).unwrap();
        let mut other = config.clone();
        other.steps += 1;
        discard_if_stale(&dir, &other).unwrap();
        assert!(!dir.exists(), "another configuration discards it");
        discard_if_stale(&dir, &other).unwrap();
    }

    #[test]
    fn the_distance_to_skinning_is_the_mean_vertex_distance() {
        // Two sequences, one step of two vertices each: distances 1, 0 and 3, 4 (m).
        let a = vec![vec![1.0, 0.0, 0.0, 5.0, 5.0, 5.0], vec![0.0, 3.0, 0.0, 0.0, 0.0, 4.0]];
        let b = vec![vec![0.0; 3].into_iter().chain([5.0; 3]).collect(), vec![0.0; 6]];
        assert!((mean_distance_mm(&a, &b) - 1e3 * 8.0 / 4.0).abs() < 1e-9);
        assert_eq!(mean_distance_mm(&b, &b), 0.0);
    }

    #[test]
    fn windows_pool_every_sample_of_their_steps() {
        let steps = vec![vec![1.0, 3.0], vec![5.0, 7.0], vec![100.0]];
        assert_eq!(window(&steps, 2), (4.0, 5.0f64.sqrt()));
        let (m, _) = window(&steps, 3);
        assert!((m - 23.2).abs() < 1e-12);
        let hundred: Vec<f64> = (1..=100).map(f64::from).rev().collect();
        assert_eq!(percentile(&hundred, 0.99), 99.0);
        assert_eq!(percentile(&hundred, 0.5), 50.0);
        assert_eq!(percentile(&[], 0.5), 0.0);
    }
}
