//! The `drape` experiment (Geng et al. §4.1 and §6, Tables 1–4; design §8) on the
//! `sleeve` scene: a pose → offsets network alone, with each projection layer applied
//! after training (`postprocess-*`), and trained through each layer (`trained-*`).
//!
//! - `network-only` is trained first; every `trained-*` model starts from its best weights
//!   and is trained on with its layer in the loss (a fine-tune: Geng et al. do not say
//!   whether they trained from scratch; this costs a fraction of it).
//! - Every model keeps the weights of its best validation SqrtMSE (Geng et al. §4.1).
//! - μ: fixed at 1, 0.1, 0.01, or learned (global, and per vertex), from 0.1; the global
//!   μ is also learned from 1 and 0.01 (Geng et al. §6.2), reported in its own table.
//!
//! Metrics per split (`train`, `validation`, `test`; docs/RESULTS.md): `sqrtmse-mm`,
//! `maxdist-mm` (means over examples), `compression-energy-error` and
//! `stretching-energy-error` (mean `|E(r) − E(r_T)|` of the edge-spring energy split by
//! compressed and stretched edges, mJ, at the quasistatic layer's stretch stiffness), and
//! on `train` the `training-seconds-per-example` of each trained model.

use std::path::Path;
use std::time::Instant;

use crate::error::Context;
use nalgebra::Vector3;
use weft_data::DrapeDataset;
use weft_nn::Device;
use weft_nn::drape::{DrapeModel, DrapeNetSettings, DrapeTensors, POSE_ANGLES, predict_each, sqrtmse_maxdist_mm};
use weft_nn::drape::{DrapeTrainingSettings, Fitted, Layer, Layers, Plan, fit};
use weft_nn::params::ParamStore;
use weft_proj::RestShape;

use super::context::EvalContext;
use crate::paper::Table;
use crate::records::{ExperimentOutput, Timing, mean_sd};
use crate::render::View;
use weft_data::Size;
use weft_data::files::{progress_bar, write_json};

const SPLITS: [&str; 3] = ["train", "validation", "test"];
/// The fixed μ of Geng et al. Table 3, with their method-name suffixes.
const FIXED_MU: [(f64, &str); 3] = [(1.0, "mu1"), (0.1, "mu0.1"), (0.01, "mu0.01")];
/// Starts of the learned global μ (Geng et al. §6.2); the method row starts at 0.1.
const MU_STARTS: [(f64, &str); 3] = [(1.0, "1"), (0.1, "0.1"), (0.01, "0.01")];

/// The training configuration of each evaluation size (standard: the library's default).
pub fn training_config(size: Size) -> DrapeTrainingSettings {
    if size != Size::Quick {
        return DrapeTrainingSettings::default();
    }
    DrapeTrainingSettings {
        net: DrapeNetSettings {
            hidden: vec![16, 32],
            offset_scale: 0.01,
        },
        pretrain_epochs: 30,
        finetune_epochs: 3,
        batch: 4,
        ..DrapeTrainingSettings::default()
    }
}

/// Geng et al. Tables 1 and 3: (train, validation, test) × (SqrtMSE, MaxDist) in mm.
fn paper_errors(method: &str) -> Option<[f64; 6]> {
    Some(match method {
        // Table 1's row [31]; Table 3 reprints the network with slightly different values.
        "network-only" => [2.5370, 10.554, 7.6060, 29.799, 7.6840, 29.637],
        "postprocess-socp" => [2.0781, 10.042, 7.2026, 28.880, 7.4326, 29.012],
        "trained-socp" => [2.0767, 9.9807, 7.1903, 29.181, 7.1603, 29.006],
        "postprocess-qs-mu1" => [2.2014, 10.333, 7.3195, 29.371, 7.2918, 29.604],
        "trained-qs-mu1" => [2.1754, 9.7121, 7.2804, 29.716, 7.2794, 31.191],
        "postprocess-qs-mu0.1" => [2.2268, 12.881, 7.2168, 30.371, 7.1879, 30.599],
        "trained-qs-mu0.1" => [1.7223, 10.864, 7.1435, 30.246, 7.1465, 31.191],
        "postprocess-qs-mu0.01" => [4.3621, 22.045, 8.8966, 34.594, 8.9365, 35.022],
        "trained-qs-mu0.01" => [2.3120, 16.303, 7.3002, 31.718, 7.3596, 32.494],
        "trained-qs-per-vertex-mu" => [1.6213, 10.969, 6.8900, 31.027, 6.9375, 31.816],
        _ => return None,
    })
}

/// Geng et al. Table 4: (train, validation, test) × (compression, stretching); the paper
/// gives no unit and does not say whether the rows are the trained postprocesses (we
/// read them so).
#[allow(clippy::approx_constant)] // 0.3183 is the paper's value, not 1/π.
fn paper_energies(method: &str) -> Option<[f64; 6]> {
    Some(match method {
        "trained-qs-mu1" => [4.5191, 1.0058, 14.612, 4.1526, 14.897, 4.0208],
        "trained-qs-mu0.1" => [0.4444, 0.4786, 1.7589, 0.4661, 1.7435, 0.4415],
        "trained-qs-mu0.01" => [1.5587, 0.3319, 1.6390, 0.6551, 1.7534, 0.6847],
        "trained-qs-per-vertex-mu" => [0.3183, 0.4580, 0.5990, 0.4289, 0.6433, 0.4717],
        _ => return None,
    })
}

/// Geng et al. §6.2: where the learned global μ converged from each start.
fn paper_learned_mu(start: &str) -> Option<f64> {
    match start {
        "1" => Some(0.1003),
        "0.1" => Some(0.0984),
        "0.01" => Some(0.0903),
        _ => None,
    }
}

/// Per-split scores of one method, over the examples its postprocess succeeded on.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Scores {
    pub sqrtmse: f64,
    /// The training loss's measure: the mean of the squared per-example SqrtMSE (mm²).
    pub loss_mm2: f64,
    pub maxdist: f64,
    pub compression: f64,
    pub stretching: f64,
    pub seconds_per_example: f64,
    /// Examples the postprocess failed on, and the first failure.
    pub failed: usize,
    pub first_error: Option<String>,
}

/// Scores `model` on `data`; returns the scores and, per scored example, its index in
/// `data` and its prediction.
pub fn score(
    model: &DrapeModel,
    data: &DrapeTensors,
    rest: &RestShape,
    k: f64,
    batch: usize,
) -> crate::Result<(Scores, Vec<(usize, Vec<f64>)>)> {
    let start = Instant::now();
    let pred = predict_each(model, data, batch)?;
    let seconds_per_example = start.elapsed().as_secs_f64() / pred.len().max(1) as f64;
    let truth = data.truths()?;
    let mut s = Scores {
        sqrtmse: 0.0,
        loss_mm2: 0.0,
        maxdist: 0.0,
        compression: 0.0,
        stretching: 0.0,
        seconds_per_example,
        failed: 0,
        first_error: None,
    };
    let mut kept = Vec::with_capacity(pred.len());
    for (i, (p, t)) in pred.into_iter().zip(&truth).enumerate() {
        let p = match p {
            Ok(p) => p,
            Err(e) => {
                s.failed += 1;
                s.first_error.get_or_insert(e);
                continue;
            }
        };
        let (e, m) = sqrtmse_maxdist_mm(&p, t)?;
        s.sqrtmse += e;
        s.loss_mm2 += e * e;
        s.maxdist += m;
        let (a, b) = (
            weft_proj::strain_summary(rest, &p, k)?,
            weft_proj::strain_summary(rest, t, k)?,
        );
        s.compression += 1e3 * (a.compression_energy - b.compression_energy).abs();
        s.stretching += 1e3 * (a.stretching_energy - b.stretching_energy).abs();
        kept.push((i, p));
    }
    crate::error::ensure!(
        !kept.is_empty(),
        "the postprocess failed on every example: {}",
        s.first_error.clone().unwrap_or_default()
    );
    let n = kept.len() as f64;
    s.sqrtmse /= n;
    s.loss_mm2 /= n;
    s.maxdist /= n;
    s.compression /= n;
    s.stretching /= n;
    Ok((s, kept))
}

fn set_split(out: &mut ExperimentOutput, split: &str) {
    if let Some(r) = out.records.last_mut() {
        r.split = Some(split.into());
    }
}

/// How far the kinematic guess r̃(θ) alone is from the truth on each split: the size of what
/// the network's offsets have to supply, and how much it varies from pose to pose.
fn guess_note(scene: &str, dataset: &DrapeDataset) -> crate::Result<String> {
    let mut parts = Vec::new();
    for split in SPLITS {
        let errors: Vec<f64> = dataset
            .examples
            .iter()
            .filter(|e| e.split == split)
            .map(|e| sqrtmse_maxdist_mm(&e.guess, &e.truth).map(|(s, _)| s))
            .collect::<Result<_, _>>()?;
        let (mean, sd) = crate::records::mean_sd(errors.iter().copied());
        let (lo, hi) = errors
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &e| (a.min(e), b.max(e)));
        parts.push(format!("{split} {mean:.2} ± {sd:.2} mm (range {lo:.2}–{hi:.2})"));
    }
    Ok(format!(
        "drape/{scene}: the kinematic guess r̃(θ) alone against the truth, SqrtMSE over examples: {}",
        parts.join("; ")
    ))
}

/// A garment the experiment runs on.
#[derive(Debug, Clone, Copy)]
struct Garment {
    /// The records' scene name.
    label: &'static str,
    /// Its dataset (`weft_data::spec`).
    dataset: &'static str,
    /// Its directory under the evaluation's `drape/` (the sleeve's is `drape/` itself,
    /// where its data and models were before the loose sleeve).
    dir: &'static str,
    /// The network's offset scale (m): the size of the offsets it predicts.
    offset_scale: f64,
    /// Seeds of every trained model beyond the quick size.
    seeds: &'static [u64],
    /// Epochs of the learned global μ from each start (the μ study, first seed) beyond
    /// the quick size.
    mu_study_epochs: usize,
}

/// The loose sleeve decides Geng et al.'s claims (issue 33): three seeds, and a μ study
/// long enough to see where μ settles. The close-fitting sleeve is kept as a second
/// scene at one seed (its network is already within a few tenths of a millimetre).
const GARMENTS: [Garment; 2] = [
    Garment {
        label: "loose-sleeve",
        dataset: weft_data::drape::LOOSE,
        dir: "loose-sleeve",
        offset_scale: 0.01,
        seeds: &[1, 2, 3],
        mu_study_epochs: 20,
    },
    Garment {
        label: "sleeve",
        dataset: weft_data::drape::NAME,
        dir: "",
        offset_scale: 0.01,
        seeds: &[1],
        mu_study_epochs: 5,
    },
];

/// The records' scene name of a drape dataset.
fn label_of(dataset: &str) -> &'static str {
    GARMENTS
        .iter()
        .find(|g| g.dataset == dataset)
        .map_or("sleeve", |g| g.label)
}

/// Fine-tuning learning rates tried on the validation split (first seed, the
/// quasistatic layer at μ = 0.1); the best is used by every `trained-*` model. In the
/// first standard run validation error rose after the first fine-tuning epoch at 1e-3.
fn finetune_rates(size: Size) -> &'static [f64] {
    if size == Size::Quick {
        &[1e-3]
    } else {
        &[1e-3, 3e-4, 1e-4]
    }
}

/// Training examples scored for the tables' train columns (the first of the split; the
/// validation and test splits are scored whole).
const TRAIN_SCORED: usize = 200;

pub fn run(ctx: &EvalContext) -> crate::Result<ExperimentOutput> {
    let mut out = ExperimentOutput::new("drape", ctx.size);
    for garment in GARMENTS {
        run_garment(ctx, &mut out, &garment).with_context(|| format!("drape on {}", garment.label))?;
    }
    // The claim is decided on the loose sleeve.
    out.seeds = seeds_of(&GARMENTS[0], ctx.size).len();
    Ok(out)
}

fn seeds_of(garment: &Garment, size: Size) -> Vec<u64> {
    if size == Size::Quick {
        vec![garment.seeds[0]]
    } else {
        garment.seeds.to_vec()
    }
}

/// One seed's trained models (by method name) and its network alone.
struct SeedRun {
    seed: u64,
    fitted: Vec<(String, Fitted)>,
}

/// Scores of a method on a split, cached beside the models: a session that stops while
/// scoring resumes without re-solving the layers. The key names the model's training
/// state, so a retrained model is scored again.
fn cached_score(path: &Path, key: &str, compute: impl FnOnce() -> crate::Result<Scores>) -> crate::Result<Scores> {
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

/// Starts the model directory `to` as a copy of `from` (a model trained under the same
/// stamp for fewer epochs, which `fit` then continues), unless `to` already holds a
/// model or `from` does not. The copy is made beside `to` and renamed into place, so an
/// interrupted copy leaves no partial model.
fn start_from_copy(from: &Path, to: &Path) -> crate::Result<()> {
    if to.exists() || !from.join("config.json").exists() {
        return Ok(());
    }
    let mut name = to.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    let partial = to.with_file_name(name);
    if partial.exists() {
        std::fs::remove_dir_all(&partial)?;
    }
    super::copy_tree(from, &partial)?;
    std::fs::rename(&partial, to)?;
    Ok(())
}

/// Checks that the model directory `copy` holds the run of `run` (their training records
/// are the same bytes): a directory left by another run under the method's name is a
/// typed error naming both, never scored under the wrong name.
fn check_same_run(run: &Path, copy: &Path) -> crate::Result<()> {
    let record = |dir: &Path| {
        let path = dir.join("training.json");
        std::fs::read(&path).with_context(|| format!("reading {}", path.display()))
    };
    if record(run)? != record(copy)? {
        return Err(crate::Error::Invalid(format!(
            "{} holds another run than the chosen fine-tuning rate's {}; move it away and rerun",
            copy.display(),
            run.display()
        )));
    }
    Ok(())
}

/// The state of a trained model, for the score cache's key.
fn state_key(f: &Fitted) -> String {
    format!(
        "epochs {} best {} at {:e}",
        f.state.epochs_done, f.state.best_epoch, f.state.best_validation
    )
}

#[allow(clippy::too_many_lines)]
fn run_garment(ctx: &EvalContext, out: &mut ExperimentOutput, garment: &Garment) -> crate::Result<()> {
    let scene = garment.label;
    let root = ctx.out.join("drape").join(garment.dir);
    let data_dir = root.join("data");
    let stopped = super::context::generate_dataset_frames(ctx, garment.dataset, &data_dir, None)
        .with_context(|| format!("{} dataset", garment.dataset))?;
    out.failures.extend(stopped);
    let gt = super::context::ground_truth_seconds(&data_dir)?;
    let dataset = DrapeDataset::load(&data_dir)?;
    let device = Device::Cpu;
    let v = dataset.sleeve.num_vertices();
    let tensors = |s: &str| DrapeTensors::of_split(&dataset, s, &device).with_context(|| format!("the {s} split"));
    let (train, validation, test) = (tensors("train")?, tensors("validation")?, tensors("test")?);
    let train_scored = train.select(&(0..train.len().min(TRAIN_SCORED)).collect::<Vec<_>>())?;
    let scored: [(&str, &DrapeTensors); 3] = [("train", &train_scored), ("validation", &validation), ("test", &test)];
    let seeds = seeds_of(garment, ctx.size);
    let base = DrapeTrainingSettings {
        net: DrapeNetSettings {
            offset_scale: garment.offset_scale,
            ..training_config(ctx.size).net
        },
        ..training_config(ctx.size)
    };
    write_json(&root.join("config.json"), &base)?;
    let layers = Layers::new(&dataset.sleeve, &base)?;
    let rest = RestShape::new(&dataset.sleeve)?;
    let k = base.quasistatic.stretch_stiffness;
    let models_of = |seed: u64| {
        let models = root.join("models");
        if seeds.len() > 1 {
            models.join(format!("seed-{seed}"))
        } else {
            models
        }
    };
    let config_of = |seed: u64, learning_rate: f64| DrapeTrainingSettings {
        seed,
        learning_rate,
        ..base.clone()
    };
    let mu_study_epochs = if ctx.size == Size::Quick {
        base.finetune_epochs
    } else {
        garment.mu_study_epochs
    };

    let train_one = |out: &mut ExperimentOutput,
                     dir: &Path,
                     name: &str,
                     layer: Layer,
                     config: &DrapeTrainingSettings,
                     init: Option<&Path>,
                     epochs: usize|
     -> crate::Result<Fitted> {
        let plan = Plan {
            name,
            layer,
            init,
            epochs,
            retrain_on_mismatch: true,
        };
        let seed = config.seed;
        let mut progress =
            crate::progress::TrainProgress::new(ctx.quiet, &format!("drape/{scene}/{name}/seed-{seed}"))?;
        let f = fit(dir, &plan, config, &layers, &train, &validation, v, &mut progress)
            .with_context(|| format!("training drape/{scene}/{name} (seed {seed})"))?;
        drop(progress);
        let (skipped, first) = f.state.skipped();
        if skipped > 0 {
            out.failures.push(format!(
                "drape/{scene}/{name}/seed-{seed}: {skipped} training batches skipped because the layer failed on \
                 them; the first: {}",
                first.unwrap_or_default()
            ));
        }
        Ok(f)
    };

    // The network alone, per seed (pretraining at the base rate).
    let mut networks = Vec::new();
    for &seed in &seeds {
        let dir = models_of(seed).join("network-only");
        let f = train_one(
            out,
            &dir,
            "network-only",
            Layer::None,
            &config_of(seed, base.learning_rate),
            None,
            base.pretrain_epochs,
        )?;
        networks.push((seed, dir, f));
    }

    // The network's data-size curve (first seed): `network-only` trained the same way on
    // the first quarter and half of the training examples, beside the whole set's.
    let mut size_rows = Vec::new();
    for n in [train.len() / 4, train.len() / 2, train.len()] {
        let seed = seeds[0];
        let owned;
        let fitted: &Fitted = if n == train.len() {
            &networks[0].2
        } else {
            let subset = train.select(&(0..n).collect::<Vec<_>>())?;
            let plan = Plan {
                name: "network-only",
                layer: Layer::None,
                init: None,
                epochs: base.pretrain_epochs,
                retrain_on_mismatch: true,
            };
            let mut progress =
                crate::progress::TrainProgress::new(ctx.quiet, &format!("drape/{scene}/network-only-{n}/seed-{seed}"))?;
            let f = fit(
                &models_of(seed).join("data-size").join(format!("n{n}")),
                &plan,
                &config_of(seed, base.learning_rate),
                &layers,
                &subset,
                &validation,
                v,
                &mut progress,
            )
            .with_context(|| format!("training drape/{scene}/network-only on {n} examples (seed {seed})"))?;
            owned = f;
            &owned
        };
        let mut row = vec![format!("{n}")];
        for data in [&validation, &test] {
            let (s, _) = score(&fitted.model, data, &rest, k, base.batch).context("scoring the data-size curve")?;
            row.push(format!("{:.3}", s.sqrtmse));
        }
        row.push(format!("{}", fitted.state.best_epoch));
        size_rows.push(row);
    }

    // The fine-tuning rate, on validation: the quasistatic layer at μ = 0.1 from the
    // first seed's network, one directory per rate.
    let (seed0, net0) = (seeds[0], networks[0].1.clone());
    let rate_dir = |lr: f64| models_of(seed0).join(format!("lr-{lr}")).join("trained-qs-mu0.1");
    let mut rate_rows = Vec::new();
    let mut rate_fits = Vec::new();
    let mut chosen = (f64::INFINITY, base.learning_rate);
    for &lr in finetune_rates(ctx.size) {
        let dir = rate_dir(lr);
        let f = train_one(
            out,
            &dir,
            "trained-qs-mu0.1",
            Layer::Quasistatic(0.1),
            &config_of(seed0, lr),
            Some(&net0),
            base.finetune_epochs,
        )?;
        let path: Vec<String> = f.state.history.iter().map(|h| format!("{:.3}", h.validation)).collect();
        rate_rows.push(vec![
            format!("{lr}"),
            format!("{:.4}", f.state.initial_validation),
            path.join(" → "),
            format!("{} ({:.4})", f.state.best_epoch, f.state.best_validation),
        ]);
        if f.state.best_validation < chosen.0 {
            chosen = (f.state.best_validation, lr);
        }
        rate_fits.push((lr, f));
    }
    let finetune_lr = chosen.1;
    // The chosen rate's model is the first seed's `trained-qs-mu0.1`: the same stamp
    // (configuration, layer, starting weights) and epochs, so it is not trained twice.
    // Its directory is copied to the method's place, so that every seed's model
    // directories hold what the tables score.
    let mut chosen_fit = rate_fits.into_iter().find(|(lr, _)| *lr == finetune_lr).map(|(_, f)| f);
    let method_dir = models_of(seed0).join("trained-qs-mu0.1");
    start_from_copy(&rate_dir(finetune_lr), &method_dir)?;
    check_same_run(&rate_dir(finetune_lr), &method_dir)?;

    // Every trained-* model per seed, fine-tuned from that seed's network.
    let mut trainings: Vec<(String, Layer)> = vec![("trained-socp".into(), Layer::Socp)];
    for (mu, suffix) in FIXED_MU {
        trainings.push((format!("trained-qs-{suffix}"), Layer::Quasistatic(mu)));
    }
    trainings.push((
        "trained-qs-per-vertex-mu".into(),
        Layer::LearnedMu {
            start: 0.1,
            per_vertex: true,
        },
    ));
    trainings.push((
        "trained-qs-learned-mu".into(),
        Layer::LearnedMu {
            start: 0.1,
            per_vertex: false,
        },
    ));
    let mut runs = Vec::new();
    for (seed, net_dir, net) in networks {
        let config = config_of(seed, finetune_lr);
        let mut fitted = vec![("network-only".to_string(), net)];
        for (name, layer) in &trainings {
            let reused = (seed == seed0 && *layer == Layer::Quasistatic(0.1))
                .then(|| chosen_fit.take())
                .flatten();
            let f = match reused {
                Some(f) => f,
                None => {
                    let dir = models_of(seed).join(name);
                    train_one(out, &dir, name, *layer, &config, Some(&net_dir), base.finetune_epochs)?
                }
            };
            fitted.push((name.clone(), f));
        }
        runs.push(SeedRun { seed, fitted });
    }

    // The μ study (Geng et al. §6.2): the learned global μ from three starts, first seed.
    let mut mu_rows = Vec::new();
    let mut final_mu = Vec::new();
    for (start, label) in MU_STARTS {
        let name = format!("learned-mu-from-{label}");
        let layer = Layer::LearnedMu {
            start,
            per_vertex: false,
        };
        let owned;
        let f: &Fitted = if label == "0.1" && mu_study_epochs == base.finetune_epochs {
            // The method's own model is this start's run.
            &runs[0]
                .fitted
                .iter()
                .find(|(n, _)| n == "trained-qs-learned-mu")
                .context("learned-μ model")?
                .1
        } else {
            let dir = models_of(seed0).join(&name);
            if label == "0.1" {
                // The method's model is this run's first epochs (the same stamp), so
                // the study continues it rather than train them again.
                start_from_copy(&models_of(seed0).join("trained-qs-learned-mu"), &dir)?;
            }
            owned = train_one(
                out,
                &dir,
                &name,
                layer,
                &config_of(seed0, finetune_lr),
                Some(&net0),
                mu_study_epochs,
            )?;
            &owned
        };
        let kept = f.mu.as_ref().and_then(|m| m.first().copied()).unwrap_or(f64::NAN);
        let path: Vec<String> = f
            .state
            .history
            .iter()
            .filter_map(|h| h.extra.get("mu").map(|&m| crate::records::three_significant(m)))
            .collect();
        let last = f
            .state
            .history
            .last()
            .and_then(|h| h.extra.get("mu").copied())
            .unwrap_or(kept);
        out.record(scene, &name, "learned-mu", last, "1", Timing::default());
        if let Some(p) = paper_learned_mu(label) {
            out.paper(p);
        }
        final_mu.push(last);
        mu_rows.push(vec![
            format!("{start}"),
            paper_learned_mu(label).map_or("—".into(), |p| format!("{p}")),
            crate::records::three_significant(kept),
            format!("{}", f.state.best_epoch),
            crate::records::three_significant(last),
            path.join(" → "),
        ]);
    }
    let (lo, hi) = final_mu
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), &m| (a.min(m), b.max(m)));

    // The methods per seed: trained models, and the seed's network with each layer after it.
    let mut no_mu = ParamStore::new(&device, 0);
    let order: Vec<String> = std::iter::once("network-only".to_string())
        .chain(["postprocess-socp".into(), "trained-socp".into()])
        .chain(
            FIXED_MU
                .iter()
                .flat_map(|(_, s)| [format!("postprocess-qs-{s}"), format!("trained-qs-{s}")]),
        )
        .chain(["trained-qs-learned-mu".into(), "trained-qs-per-vertex-mu".into()])
        .collect();
    // Per method and split, one `Scores` per seed.
    let mut table: Vec<(String, Vec<Vec<Scores>>, Vec<f64>)> = order
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
                post: layers.postprocess(Layer::Socp, &mut no_mu, v)?,
            },
            state_key(network),
            None,
        ));
        for (mu, suffix) in FIXED_MU {
            methods.push((
                format!("postprocess-qs-{suffix}"),
                DrapeModel {
                    net: network.model.net.clone(),
                    post: layers.postprocess(Layer::Quasistatic(mu), &mut no_mu, v)?,
                },
                state_key(network),
                None,
            ));
        }
        for (method, model, key, f) in &methods {
            let Some(row) = table.iter_mut().find(|(m, _, _)| m == method) else {
                continue;
            };
            for (k_split, (split, data)) in scored.iter().enumerate() {
                // The first seed's test predictions are written out (and its timing is the
                // Pareto plot's), so that one is always scored afresh.
                let fresh = r == 0 && *split == "test";
                let cache = root
                    .join("scores")
                    .join(format!("seed-{}", run.seed))
                    .join(format!("{method}-{split}.json"));
                let s = if fresh {
                    let (s, pred) =
                        score(model, data, &rest, k, base.batch).with_context(|| format!("scoring {method}"))?;
                    write_predictions(ctx, scene, method, data, &pred)?;
                    s
                } else {
                    cached_score(&cache, &format!("{key}; {} examples", data.len()), || {
                        Ok(score(model, data, &rest, k, base.batch)
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
                row.2.push(f.state.median_epoch_seconds() / train.len().max(1) as f64);
            }
        }
    }
    bar.finish_and_clear();

    // Records and tables: the mean over seeds, the `-sd` record their spread.
    let many = seeds.len() > 1;
    let mut error_rows = Vec::new();
    let mut energy_rows = Vec::new();
    let mut time_rows = Vec::new();
    for (method, per_split, train_seconds) in &table {
        let mut error_row = vec![format!("`{method}`")];
        let mut energy_row = vec![format!("`{method}`")];
        for (k_split, (split, _)) in scored.iter().enumerate() {
            let seeds_scores = &per_split[k_split];
            if seeds_scores.is_empty() {
                continue;
            }
            // The first seed's time per example (its test split was scored afresh).
            let timing = Timing::new(seeds_scores[0].seconds_per_example, gt);
            let paper = paper_errors(method);
            let energies = paper_energies(method);
            let mut cells = Vec::new();
            for (metric, of, unit, p) in [
                (
                    "sqrtmse-mm",
                    (|s: &Scores| s.sqrtmse) as fn(&Scores) -> f64,
                    "mm",
                    paper.map(|r| r[2 * k_split]),
                ),
                (
                    "maxdist-mm",
                    |s: &Scores| s.maxdist,
                    "mm",
                    paper.map(|r| r[2 * k_split + 1]),
                ),
                (
                    "compression-energy-error",
                    |s: &Scores| s.compression,
                    "mJ",
                    energies.map(|r| r[2 * k_split]),
                ),
                (
                    "stretching-energy-error",
                    |s: &Scores| s.stretching,
                    "mJ",
                    energies.map(|r| r[2 * k_split + 1]),
                ),
            ] {
                let (m, sd) = mean_sd(seeds_scores.iter().map(of));
                out.record(scene, method, metric, m, unit, timing);
                if let Some(p) = p {
                    out.paper(p);
                }
                set_split(out, split);
                if many {
                    out.record(scene, method, &format!("{metric}-sd"), sd, unit, Timing::default());
                    set_split(out, split);
                }
                let ours = if many {
                    crate::records::mean_and_spread(m, sd)
                } else {
                    crate::records::three_significant(m)
                };
                cells.push(match p {
                    Some(p) => format!("{p:.3} / {ours}"),
                    None => format!("— / {ours}"),
                });
            }
            error_row.extend(cells[..2].iter().cloned());
            energy_row.extend(cells[2..].iter().cloned());
        }
        if !train_seconds.is_empty() {
            let (m, _) = mean_sd(train_seconds.iter().copied());
            let paper = paper_training_seconds(method);
            out.record(scene, method, "training-seconds-per-example", m, "s", Timing::default());
            if let Some(p) = paper {
                out.paper(p);
            }
            set_split(out, "train");
            time_rows.push(vec![
                format!("`{method}`"),
                paper.map_or("—".into(), |p| format!("{p}")),
                format!("{m:.4}"),
            ]);
        }
        error_rows.push(error_row);
        energy_rows.push(energy_row);
    }
    let c = &base;
    out.notes.push(format!(
        "drape/{scene}: {v} vertices on the skinned limb (m, scored in mm); {} / {} / {} train / validation / test \
         examples (the train columns score the first {}); {} seed(s) {:?} per model{}; network {:?} (offsets × {} m); \
         network-only trained {} epochs at lr {}, each trained-* model {} more from its seed's best weights with its \
         layer in the loss at the fine-tuning rate chosen on validation, {finetune_lr}; weights of the best validation \
         SqrtMSE kept; batch {}, log μ lr {}; SOCP ε = {}; quasistatic k_L {}, k_B {}, k_A {}, k_Z {} N/m; energies \
         at k = {k} N/m in mJ; time per example of the method (first seed) on this machine against the ground truth's \
         wall time per example (two threads) from the dataset's timing.json",
        train.len(),
        validation.len(),
        test.len(),
        train_scored.len(),
        seeds.len(),
        seeds,
        if many {
            " (each figure their mean, its `-sd` record their spread)"
        } else {
            ""
        },
        c.net.hidden,
        c.net.offset_scale,
        c.pretrain_epochs,
        c.learning_rate,
        c.finetune_epochs,
        c.batch,
        c.mu_learning_rate,
        c.epsilon,
        c.quasistatic.stretch_stiffness,
        c.quasistatic.bend_stiffness,
        c.quasistatic.axial_stiffness,
        c.quasistatic.zero_length_stiffness,
    ));
    out.notes.push(guess_note(scene, &dataset)?);
    out.notes.push(format!(
        "drape/{scene}: the learned global μ after {mu_study_epochs} epochs from starts 1, 0.1 and 0.01 (seed {seed0}): \
         {} — largest / smallest {:.2}",
        final_mu.iter().map(|&m| crate::records::three_significant(m)).collect::<Vec<_>>().join(", "),
        hi / lo
    ));
    let header = |a: &str, b: &str| {
        let mut h = vec!["method".to_string()];
        for s in SPLITS {
            h.push(format!("{s} {a}"));
            h.push(format!("{s} {b}"));
        }
        h
    };
    let spread = if many { " Ours: mean ± sd over the seeds." } else { "" };
    out.tables.push(Table {
        title: format!("Geng et al. Tables 1 and 3 on `{scene}` — SqrtMSE and MaxDist (mm), paper / ours"),
        caption: format!(
            "The paper's shirt (1000 training examples) beside our {scene}; `network-only` is the paper's row [31] \
             (Table 1's values). Means over examples of each split.{spread}"
        ),
        header: header("SqrtMSE", "MaxDist"),
        rows: error_rows,
    });
    out.tables.push(Table {
        title: format!(
            "Geng et al. Table 4 on `{scene}` — compression and stretching energy errors, paper / ours (mJ)"
        ),
        caption: format!(
            "Mean |E(r) − E(r_T)| over the compressed and the stretched edges of the edge-spring energy at k_L. The \
             paper prints no unit; its rows are read as the trained quasistatic postprocesses.{spread}"
        ),
        header: header("compression", "stretching"),
        rows: energy_rows,
    });
    out.tables.push(Table {
        title: format!("Training time per example on `{scene}` (s), paper / ours"),
        caption: "Wall seconds per training example and epoch (each model's median epoch), mean over the seeds; \
                  the paper's figures are its \
                  forward plus backward time per example (Geng et al. §4.1 for the SOCP, §6.1 for the quasistatic \
                  layer) on its machine."
            .into(),
        header: vec!["method".into(), "paper".into(), "ours".into()],
        rows: time_rows,
    });
    out.tables.push(Table {
        title: format!("`network-only`'s data-size curve on `{scene}` — SqrtMSE (mm)"),
        caption: format!(
            "Seed {seed0}: the network alone trained on the first n training examples ({} epochs, the weights of \
             the best validation SqrtMSE kept), scored on the whole validation and test splits.",
            base.pretrain_epochs
        ),
        header: vec![
            "training examples".into(),
            "validation".into(),
            "test".into(),
            "kept epoch".into(),
        ],
        rows: size_rows,
    });
    out.tables.push(Table {
        title: format!("Fine-tuning learning rate on `{scene}` — validation SqrtMSE (mm)"),
        caption: format!(
            "`trained-qs-mu0.1` from seed {seed0}'s network at each rate: the starting weights' validation SqrtMSE, \
             then after each epoch, and the kept epoch. The lowest kept score chooses the rate of every trained-* \
             model ({finetune_lr}); the test split plays no part."
        ),
        header: vec!["rate".into(), "start".into(), "per epoch".into(), "kept".into()],
        rows: rate_rows,
    });
    out.tables.push(Table {
        title: format!("Geng et al. §6.2 on `{scene}` — the learned global μ from three starts"),
        caption: format!(
            "Seed {seed0}, {mu_study_epochs} epochs: μ at the kept (best validation) epoch, after the last epoch, \
             and after every epoch."
        ),
        header: vec![
            "start".into(),
            "paper".into(),
            "kept".into(),
            "kept epoch".into(),
            "last".into(),
            "per epoch".into(),
        ],
        rows: mu_rows,
    });
    if let Some((_, f)) = runs[0].fitted.iter().find(|(n, _)| n == "trained-qs-per-vertex-mu") {
        if let Some(mu) = &f.mu {
            render_mu(ctx, out, scene, &dataset, mu)?;
        }
    }
    Ok(())
}

/// Geng et al.'s training time per example (s): forward plus backward through the layer,
/// §4.1 (the SOCP: 3–4 s and 0.5 s; we take 4) and §6.1 (the quasistatic layer: 0.07 s and
/// 0.01 s).
fn paper_training_seconds(method: &str) -> Option<f64> {
    if method == "trained-socp" {
        Some(4.0)
    } else if method.starts_with("trained-qs") {
        Some(0.08)
    } else {
        None
    }
}

/// Test-split predictions `r*` of a method beside the ground truth and the poses (the
/// examples its postprocess succeeded on, with their indices in the split).
fn write_predictions(
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

/// Geng et al. Fig. 10: the learned per-vertex μ_i on the rest sleeve, a PNG in the report
/// and a PLY with per-vertex colours (the colour scale runs to the largest μ_i).
fn render_mu(
    ctx: &EvalContext,
    out: &mut ExperimentOutput,
    scene: &str,
    dataset: &DrapeDataset,
    mu: &[f64],
) -> crate::Result<()> {
    let dir = Path::new("renders").join("drape").join(scene);
    std::fs::create_dir_all(ctx.out.join(&dir))?;
    // μ_i spans decades (a few vertices far above the median), so the map is logarithmic.
    let mut sorted = mu.to_vec();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN);
    let x = dataset.sleeve.flat_positions();
    let png = dir.join("per-vertex-mu.png");
    crate::render::log_scale_png(
        &ctx.out.join(&png),
        &x,
        dataset.sleeve.faces(),
        mu,
        "μ",
        &format!(
            "{scene} — learned μ_i (median {})",
            crate::records::three_significant(median)
        ),
        View::BEAM,
    )?;
    out.renders.push(png.display().to_string());
    let points: Vec<Vector3<f64>> = dataset.sleeve.positions().to_vec();
    let (fractions, _) = crate::render::log_scale(mu, "μ")?;
    weft_mesh::io::write_ply(
        &ctx.out.join(dir.join("per-vertex-mu.ply")),
        &points,
        dataset.sleeve.faces(),
        Some(&crate::render::bar_colors(&fractions)),
    )?;
    Ok(())
}

/// The evaluation's method name of a model trained through `layer`.
pub fn method_name(layer: Layer) -> String {
    match layer {
        Layer::None => "network-only".into(),
        Layer::Socp => "trained-socp".into(),
        Layer::Quasistatic(mu) => FIXED_MU
            .iter()
            .find(|(m, _)| *m == mu)
            .map_or_else(|| format!("trained-qs-mu{mu}"), |(_, s)| format!("trained-qs-{s}")),
        Layer::LearnedMu { per_vertex: true, .. } => "trained-qs-per-vertex-mu".into(),
        Layer::LearnedMu { start: 0.1, .. } => "trained-qs-learned-mu".into(),
        Layer::LearnedMu { start, .. } => format!("learned-mu-from-{start}"),
    }
}

/// Scores the model in `model_dir` (`cargo xtask train drape`, or one of the evaluation's)
/// on the `split` examples of the `drape` dataset in `data_dir`, with the evaluation's
/// metrics (`sqrtmse-mm`, `maxdist-mm`, `compression-energy-error`,
/// `stretching-energy-error`; cold layer solves) and its predictions under
/// `ctx.out/predictions/drape/sleeve/`. Examples the layer fails on are left out and
/// reported in the output's failures.
pub fn score_model(
    ctx: &EvalContext,
    model_dir: &Path,
    data_dir: &Path,
    split: &str,
) -> crate::Result<ExperimentOutput> {
    let dataset = DrapeDataset::load(data_dir)?;
    let (model, layer, config) = weft_nn::drape::load_model(model_dir, &dataset.sleeve)
        .with_context(|| format!("loading the model in {}", model_dir.display()))?;
    let data = DrapeTensors::of_split(&dataset, split, &Device::Cpu)?;
    crate::error::ensure!(!data.is_empty(), "{} has no {split} example", data_dir.display());
    let rest = RestShape::new(&dataset.sleeve)?;
    let (s, pred) = score(&model, &data, &rest, config.quasistatic.stretch_stiffness, config.batch)?;
    let method = method_name(layer);
    let scene = label_of(&dataset.name);
    let mut out = ExperimentOutput::new("drape", ctx.size);
    out.notes.push(format!(
        "drape score: {} ({layer}) on the {} {split} examples of {}",
        model_dir.display(),
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
        ground_truth_seconds_per_frame: super::context::ground_truth_seconds(data_dir).ok(),
    };
    for (metric, value, unit) in [
        ("sqrtmse-mm", s.sqrtmse, "mm"),
        ("maxdist-mm", s.maxdist, "mm"),
        ("compression-energy-error", s.compression, "mJ"),
        ("stretching-energy-error", s.stretching, "mJ"),
    ] {
        out.record(scene, &method, metric, value, unit, timing);
        set_split(&mut out, split);
    }
    write_predictions(ctx, scene, &method, &data, &pred)?;
    Ok(out)
}

/// What `cargo xtask train drape` reports of a model it trained: batches the layer failed
/// on, the last epoch, the kept model scored on the validation and test splits with cold
/// solves as the evaluation scores it (`scores.json`), the second half of training (the
/// validation error's scatter, the last μ, the strength of μ's gradient against its noise),
/// and with `scan_mu` the validation loss of the kept network at each fixed μ
/// (`mu-scan.json`; docs/DRAPE.md, the μ study).
#[allow(clippy::too_many_arguments)]
pub fn summarize_trained(
    out: &Path,
    name: &str,
    fitted: &Fitted,
    layers: &Layers,
    config: &DrapeTrainingSettings,
    validation: &DrapeTensors,
    test: &DrapeTensors,
    sleeve: &weft_mesh::TriMesh,
    scan_mu: &[f64],
) -> crate::Result<()> {
    let p = &fitted.state;
    let (skipped, first) = p.skipped();
    if skipped > 0 {
        eprintln!(
            "drape/{name}: {skipped} training batches skipped because the layer failed on them; the first: {}",
            first.unwrap_or_default()
        );
    }
    // The kept model, scored with cold solves as the evaluation scores it.
    let rest = RestShape::new(sleeve)?;
    let k = config.quasistatic.stretch_stiffness;
    let mut scores = serde_json::Map::new();
    for (split, data) in [("validation", validation), ("test", test)] {
        if data.is_empty() {
            continue;
        }
        let (s, _) = score(&fitted.model, data, &rest, k, config.batch)?;
        eprintln!(
            "drape/{name}: kept epoch {}: {split} SqrtMSE {:.4} mm, MaxDist {:.4} mm ({} examples failed)",
            p.best_epoch, s.sqrtmse, s.maxdist, s.failed
        );
        scores.insert(
            split.into(),
            serde_json::json!({
                "sqrtmse-mm": s.sqrtmse,
                "maxdist-mm": s.maxdist,
                "compression-energy-error": s.compression,
                "stretching-energy-error": s.stretching,
                "failed": s.failed,
            }),
        );
    }
    let mu = fitted
        .mu
        .as_ref()
        .map(|m| m.iter().sum::<f64>() / m.len().max(1) as f64);
    // Where training settles, over its second half: how much the validation error scatters
    // from epoch to epoch, where μ ends and how strong μ's gradient is against its noise
    // (the median over epochs of |mean| / sd of the per-batch gradient).
    let late = &p.history[p.history.len() / 2..];
    let (val_mean, val_sd) = crate::records::mean_sd(late.iter().map(|h| h.validation));
    let mut signal: Vec<f64> = late
        .iter()
        .filter_map(|h| Some((*h.extra.get("mu_gradient_mean")?, *h.extra.get("mu_gradient_sd")?)))
        .filter(|(_, sd)| *sd > 0.0)
        .map(|(mean, sd)| mean.abs() / sd)
        .collect();
    signal.sort_by(f64::total_cmp);
    let second_half = serde_json::json!({
        "epochs": [p.history.len() / 2 + 1, p.history.len()],
        "validation_sqrtmse_mm_mean": val_mean,
        "validation_sqrtmse_mm_sd": val_sd,
        "last_mu": late.last().and_then(|h| h.extra.get("mu")),
        "mu_gradient_mean_over_sd_median": signal.get(signal.len() / 2),
    });
    if late.len() > 1 {
        eprintln!(
            "drape/{name}: epochs {}-{}: validation SqrtMSE {val_mean:.4} ± {val_sd:.4} mm{}",
            p.history.len() / 2 + 1,
            p.history.len(),
            signal
                .get(signal.len() / 2)
                .map_or(String::new(), |s| format!(", μ gradient median |mean|/sd {s:.3}"))
        );
    }
    weft_data::files::write_text(
        &out.join("scores.json"),
        &serde_json::to_string_pretty(&serde_json::json!({
            "kept_epoch": p.best_epoch,
            "epochs": p.epochs_done,
            "kept_mu_mean": mu,
            "second_half": second_half,
            "scores": scores,
        }))?,
    )?;
    if !scan_mu.is_empty() {
        // The same cold solves as the scores: the loss (mean squared SqrtMSE, mm²) and the
        // SqrtMSE of the kept network as μ alone varies.
        let mut scan = Vec::with_capacity(scan_mu.len());
        for &m in scan_mu {
            let (s, _) = score(
                &layers.at_fixed_mu(&fitted.model.net, m),
                validation,
                &rest,
                k,
                config.batch,
            )?;
            let loss = s.loss_mm2;
            eprintln!(
                "drape/{name}: μ = {m}: validation SqrtMSE {:.4} mm, loss {loss:.5} mm² ({} examples failed)",
                s.sqrtmse, s.failed
            );
            scan.push(serde_json::json!({
                "mu": m,
                "validation_sqrtmse_mm": s.sqrtmse,
                "validation_loss_mm2": loss,
                "failed": s.failed,
            }));
        }
        weft_data::files::write_text(
            &out.join("mu-scan.json"),
            &serde_json::to_string_pretty(&serde_json::json!({
                "kept_epoch": p.best_epoch,
                "kept_mu_mean": mu,
                "scan": scan,
            }))?,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;

    #[test]
    fn scored_models_are_named_as_the_evaluation_names_them() {
        assert_eq!(method_name(Layer::None), "network-only");
        assert_eq!(method_name(Layer::Quasistatic(0.1)), "trained-qs-mu0.1");
        assert_eq!(method_name(Layer::Quasistatic(0.5)), "trained-qs-mu0.5");
        let learned = |start, per_vertex| method_name(Layer::LearnedMu { start, per_vertex });
        assert_eq!(learned(0.1, false), "trained-qs-learned-mu");
        assert_eq!(learned(1.0, false), "learned-mu-from-1");
        assert_eq!(learned(0.1, true), "trained-qs-per-vertex-mu");
    }

    #[test]
    fn a_model_directory_is_copied_whole_once_and_never_over_a_model() {
        let root = std::env::temp_dir().join(format!("weft-drape-copy-{}", std::process::id()));
        let (from, to) = (root.join("trained-qs-learned-mu"), root.join("learned-mu-from-0.1"));
        let write = |path: &Path, text: &str| {
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, text).unwrap();
        };
        // No model to copy yet: nothing is made.
        start_from_copy(&from, &to).unwrap();
        assert!(!to.exists());
        write(&from.join("config.json"), "stamp");
        write(&from.join("last/net/params.safetensors"), "weights");
        write(&from.join("best/net/state.json"), "best");
        // A partial copy left by an interrupted run is replaced.
        write(&root.join("learned-mu-from-0.1.partial/config.json"), "stale");
        start_from_copy(&from, &to).unwrap();
        let read = |path: PathBuf| std::fs::read_to_string(path).unwrap();
        assert_eq!(read(to.join("config.json")), "stamp");
        assert_eq!(read(to.join("last/net/params.safetensors")), "weights");
        assert_eq!(read(to.join("best/net/state.json")), "best");
        assert!(!root.join("learned-mu-from-0.1.partial").exists());
        // A model already there (being continued) is never overwritten.
        write(&from.join("last/net/params.safetensors"), "newer");
        write(&to.join("last/net/params.safetensors"), "continued");
        start_from_copy(&from, &to).unwrap();
        assert_eq!(read(to.join("last/net/params.safetensors")), "continued");
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn the_method_directory_must_hold_the_chosen_rate_run() {
        let root = std::env::temp_dir().join(format!("weft-drape-same-run-{}", std::process::id()));
        let (run, copy) = (root.join("lr-0.0001"), root.join("trained-qs-mu0.1"));
        for dir in [&run, &copy] {
            std::fs::create_dir_all(dir).unwrap();
        }
        std::fs::write(run.join("training.json"), "lr 1e-4 history").unwrap();
        // No record in the method's directory: an error, not a pass.
        assert!(check_same_run(&run, &copy).is_err());
        // Another rate's run left there (the layout before the rate directories).
        std::fs::write(copy.join("training.json"), "lr 1e-3 history").unwrap();
        let message = check_same_run(&run, &copy).unwrap_err().to_string();
        assert!(
            message.contains("trained-qs-mu0.1") && message.contains("lr-0.0001"),
            "{message}"
        );
        std::fs::write(copy.join("training.json"), "lr 1e-4 history").unwrap();
        check_same_run(&run, &copy).unwrap();
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn paper_rows_are_geng_et_al_tables() {
        // Table 1 row [31], test SqrtMSE; Table 3 μ = 0.1 trained, train SqrtMSE.
        assert_eq!(paper_errors("network-only").unwrap()[4], 7.6840);
        assert_eq!(paper_errors("trained-qs-mu0.1").unwrap()[0], 1.7223);
        // Table 4, variable μ_i, test stretching.
        assert_eq!(paper_energies("trained-qs-per-vertex-mu").unwrap()[5], 0.4717);
        assert_eq!(paper_energies("postprocess-socp"), None);
        assert_eq!(paper_learned_mu("0.01"), Some(0.0903));
    }
}
