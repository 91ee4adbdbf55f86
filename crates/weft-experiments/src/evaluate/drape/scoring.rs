//! The drape experiment's scoring: a model's scores on a split (SqrtMSE, MaxDist and the
//! energy errors, over the examples its layer succeeded on), cached beside the models;
//! every method of every seed scored on the tables' splits; the test predictions; and
//! [`score_model`] for a model trained outside the evaluation.

use std::path::Path;

use weft_data::DrapeDataset;
use weft_data::files::progress_bar;
use weft_nn::Device;
use weft_nn::drape::{DrapeModel, DrapeTensors, POSE_ANGLES};
use weft_nn::drape::{Fitted, Layer};
use weft_nn::params::ParamStore;
use weft_proj::RestShape;

use super::data::GarmentData;
use super::studies::SeedRun;
use super::{CONTROL, FIXED_MU, label_of, method_name};
use crate::error::Context;
use crate::evaluate::context::{EvalContext, Scoring};
use crate::records::{ExperimentOutput, Timing};

/// Per method, one [`Scores`] per seed for each of the tables' splits, and each trained
/// model's training seconds per example (one per seed).
pub(super) type MethodScores = Vec<(String, Vec<Vec<Scores>>, Vec<f64>)>;

/// The methods of the tables, in their order.
fn method_order() -> Vec<String> {
    ["network-only".to_string(), CONTROL.into()]
        .into_iter()
        .chain(["postprocess-socp".into(), "trained-socp".into()])
        .chain(
            FIXED_MU
                .iter()
                .flat_map(|(_, s)| [format!("postprocess-qs-{s}"), format!("trained-qs-{s}")]),
        )
        .chain(["trained-qs-learned-mu".into(), "trained-qs-per-vertex-mu".into()])
        .collect()
}

/// The methods of one seed: its trained models, and its network with each layer after it;
/// each with its score cache key and, if trained, the fit.
fn seed_methods<'a>(
    g: &GarmentData,
    run: &'a SeedRun,
) -> crate::Result<Vec<(String, DrapeModel, String, Option<&'a Fitted>)>> {
    let mut no_mu = ParamStore::new(&Device::Cpu, 0);
    let network = &run.fitted[0].1;
    let mut methods: Vec<(String, DrapeModel, String, Option<&Fitted>)> = run
        .fitted
        .iter()
        .map(|(n, f)| (n.clone(), f.model.clone(), state_key(f), Some(f)))
        .collect();
    methods.push((
        "postprocess-socp".into(),
        DrapeModel {
            net: network.model.net.clone(),
            post: g.layers.postprocess(Layer::Socp, &mut no_mu, g.v)?,
        },
        state_key(network),
        None,
    ));
    for (mu, suffix) in FIXED_MU {
        methods.push((
            format!("postprocess-qs-{suffix}"),
            DrapeModel {
                net: network.model.net.clone(),
                post: g.layers.postprocess(Layer::Quasistatic(mu), &mut no_mu, g.v)?,
            },
            state_key(network),
            None,
        ));
    }
    Ok(methods)
}

/// Every method of every seed scored on the tables' splits (the first seed's test split
/// afresh, with its predictions written; the rest through the score cache); examples a
/// layer failed on go to `out`'s failures.
pub(super) fn score_methods(
    ctx: &EvalContext,
    g: &GarmentData,
    out: &mut ExperimentOutput,
    runs: &[SeedRun],
) -> crate::Result<MethodScores> {
    let (scene, k) = (g.scene, g.k());
    let scored = g.scored();
    let order = method_order();
    // Per method and split, one `Scores` per seed.
    let mut table: MethodScores = order
        .iter()
        .map(|m| (m.clone(), vec![Vec::new(); 3], Vec::new()))
        .collect();
    let bar = progress_bar(
        ctx.quiet,
        (runs.len() * order.len() * scored.iter().map(|(_, d)| d.len()).sum::<usize>()) as u64,
        &format!("drape/{scene} scoring"),
        "examples",
    )?;
    for (r, run) in runs.iter().enumerate() {
        for (method, model, key, f) in &seed_methods(g, run)? {
            let Some(row) = table.iter_mut().find(|(m, _, _)| m == method) else {
                continue;
            };
            for (k_split, (split, data)) in scored.iter().enumerate() {
                // The first seed's test predictions are written out (and its timing is the
                // Pareto plot's), so that one is always scored afresh.
                let fresh = r == 0 && *split == "test";
                let cache = g
                    .root
                    .join("scores")
                    .join(format!("seed-{}", run.seed))
                    .join(format!("{method}-{split}.json"));
                let s = if fresh {
                    let (s, pred) =
                        score(model, data, &g.rest, k, g.base.batch).with_context(|| format!("scoring {method}"))?;
                    write_predictions(ctx, scene, method, data, &pred)?;
                    s
                } else {
                    cached_score(&cache, &format!("{key}; {} examples", data.len()), || {
                        Ok(score(model, data, &g.rest, k, g.base.batch)
                            .with_context(|| format!("scoring {method}"))?
                            .0)
                    })?
                };
                bar.inc(data.len() as u64);
                if s.failed > 0 {
                    out.failures.push(format!(
                        "drape/{scene}/{method}/{split}/seed-{}: the postprocess failed on {} of {} examples, which \
                         are left out of its scores; the first: {}",
                        run.seed,
                        s.failed,
                        data.len(),
                        s.first_error.clone().unwrap_or_default()
                    ));
                }
                row.1[k_split].push(s);
            }
            if let Some(f) = f {
                // The median epoch (a paused or shared epoch does not move it).
                row.2.push(f.state.median_epoch_seconds() / g.train.len().max(1) as f64);
            }
        }
    }
    bar.finish_and_clear();
    Ok(table)
}

/// Per-split scores of one method and the function that computes them: weft-nn's, the
/// same that `cargo xtask train drape` reports.
pub use weft_nn::drape::{Scores, score};

/// Scores of a method on a split, cached beside the models: a session that stops while
/// scoring resumes without re-solving the layers. The key names the model's training
/// state, so a retrained model is scored again.
pub(super) fn cached_score(
    path: &Path,
    key: &str,
    compute: impl FnOnce() -> crate::Result<Scores>,
) -> crate::Result<Scores> {
    if let Ok(text) = std::fs::read_to_string(path) {
        if let Ok(v) = serde_json::from_str::<serde_json::Value>(&text) {
            if v["key"] == key {
                if let Ok(s) = serde_json::from_value(v["scores"].clone()) {
                    return Ok(s);
                }
            }
        }
    }
    let s = compute()?;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    weft_data::files::write_text(
        path,
        &serde_json::to_string_pretty(&serde_json::json!({"key": key, "scores": s}))?,
    )?;
    Ok(s)
}

/// The state of a trained model, for the score cache's key.
pub(super) fn state_key(f: &Fitted) -> String {
    format!(
        "epochs {} best {} at {:e}",
        f.state.epochs_done, f.state.best_epoch, f.state.best_validation
    )
}

/// Test-split predictions `r*` of a method beside the ground truth and the poses (the
/// examples its postprocess succeeded on, with their indices in the split).
pub(super) fn write_predictions(
    ctx: &EvalContext,
    scene: &str,
    method: &str,
    data: &DrapeTensors,
    pred: &[(usize, Vec<f64>)],
) -> crate::Result<()> {
    let dir = ctx.out.join("predictions").join("drape").join(scene);
    std::fs::create_dir_all(&dir)?;
    let v = pred.first().map_or(0, |p| p.1.len() / 3);
    let shape = vec![pred.len(), v, 3];
    let truths = data.truths()?;
    let poses = data.poses()?;
    let index: Vec<i64> = pred.iter().map(|(i, _)| *i as i64).collect();
    let mut meta = std::collections::HashMap::new();
    meta.insert(
        "units".into(),
        "positions (r*, the method's output) and ground_truth (r_T) [examples, vertices, 3] in metres, the `test` \
         split of the drape dataset, vertices as in its sleeve.obj; pose [examples, 4] in radians (shoulder flexion, abduction, twist, elbow flexion); example_index \
         [examples]: each example's index in the split"
            .into(),
    );
    Ok(weft_data::files::write_safetensors(
        &dir.join(format!("{method}.safetensors")),
        &[
            weft_data::files::Array::f64(
                "positions",
                shape.clone(),
                &pred.iter().flat_map(|p| p.1.iter().copied()).collect::<Vec<_>>(),
            ),
            weft_data::files::Array::f64(
                "ground_truth",
                shape,
                &pred
                    .iter()
                    .flat_map(|(i, _)| truths[*i].iter().copied())
                    .collect::<Vec<_>>(),
            ),
            weft_data::files::Array::f64(
                "pose",
                vec![pred.len(), POSE_ANGLES],
                &pred
                    .iter()
                    .flat_map(|(i, _)| poses[POSE_ANGLES * i..POSE_ANGLES * (i + 1)].iter().copied())
                    .collect::<Vec<_>>(),
            ),
            weft_data::files::Array::i64("example_index", &index),
        ],
        meta,
    )?)
}

/// Scores the model in `model_dir` (`cargo xtask train drape`, or one of the evaluation's)
/// on the `split` examples of the `drape` dataset in `data_dir`, with the evaluation's
/// metrics (`sqrtmse-mm`, `maxdist-mm`, `compression-energy-error`,
/// `stretching-energy-error`; cold layer solves) and its predictions under
/// `ctx.out/predictions/drape/sleeve/`. Examples the layer fails on are left out and
/// reported in the output's failures.
pub fn score_model(scoring: &Scoring) -> crate::Result<ExperimentOutput> {
    let (ctx, data_dir, split) = (scoring.ctx, scoring.data_dir, scoring.split);
    let dataset = DrapeDataset::load(data_dir)?;
    let (model, layer, config) = scoring.load_model(|dir| weft_nn::drape::load_model(dir, &dataset.sleeve))?;
    let data = DrapeTensors::of_split(&dataset, split, &Device::Cpu)?;
    scoring.require(data.len(), "example")?;
    let rest = RestShape::new(&dataset.sleeve)?;
    let (s, pred) = score(&model, &data, &rest, config.quasistatic.stretch_stiffness, config.batch)?;
    let method = method_name(layer);
    let scene = label_of(&dataset.name);
    let mut out = scoring.output(format_args!(
        "({layer}) on the {} {split} examples of {}",
        data.len(),
        data_dir.display()
    ));
    if s.failed > 0 {
        out.failures.push(format!(
            "drape/{method}/{split}: the postprocess failed on {} of {} examples, left out of its scores; the first: {}",
            s.failed,
            data.len(),
            s.first_error.clone().unwrap_or_default()
        ));
    }
    let timing = Timing {
        seconds_per_frame: Some(s.seconds_per_example),
        ground_truth_seconds_per_frame: scoring.ground_truth_seconds(),
    };
    for (metric, value, unit) in [
        ("sqrtmse-mm", s.sqrtmse, "mm"),
        ("maxdist-mm", s.maxdist, "mm"),
        ("compression-energy-error", s.compression, "mJ"),
        ("stretching-energy-error", s.stretching, "mJ"),
    ] {
        out.record(scene, &method, metric, value, unit, timing);
        out.split(split);
    }
    write_predictions(ctx, scene, &method, &data, &pred)?;
    Ok(out)
}
