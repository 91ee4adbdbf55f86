//! The altconv experiment's studies: every variant trained with every seed, the learning
//! rate chosen on validation with the first seed, each model's training time and the
//! validation curves.

use std::path::{Path, PathBuf};

use weft_data::LimbDataset;
use weft_nn::altconv::{AltConvTrainingSettings, Variant};
use weft_nn::trainer::TrainingState;

use super::{learning_rates, training_config};
use crate::error::Context;
use crate::evaluate::context::EvalContext;
use crate::evaluate::study::Study;
use crate::records::{ExperimentOutput, Series, Timing, mean_sd};

/// Every variant's trained models, and what the tables show of their training.
pub(super) struct Trained {
    /// Per variant, its models (one per seed) with the best validation score first.
    pub models: Vec<(Variant, Vec<(f64, PathBuf)>)>,
    /// Per variant, the first seed's best validation score at each rate and the chosen
    /// rate (empty with one rate).
    pub rate_rows: Vec<Vec<String>>,
    /// Per variant, the validation error after each epoch, mean over the seeds (mm).
    pub curves: Vec<Series>,
}

/// One variant's models on one scene, each trained (or resumed) into its directory.
struct VariantTraining<'a> {
    ctx: &'a EvalContext,
    scene: &'a str,
    variant: Variant,
    dataset: &'a LimbDataset,
    /// `models/<variant>/` under the scene's directory.
    dir: PathBuf,
    rates: &'a [f64],
}

impl VariantTraining<'_> {
    /// Trains the model of `seed` at learning rate `lr`; returns its training record and
    /// directory.
    fn train(&self, seed: u64, lr: f64) -> crate::Result<(TrainingState, PathBuf)> {
        let (scene, variant) = (self.scene, self.variant);
        let mut config = AltConvTrainingSettings {
            seed,
            ..training_config(self.ctx.size, scene, variant)
        };
        config.adam.learning_rate = lr;
        // One rate keeps the layout the models had before there was a choice.
        let model_dir = if self.rates.len() > 1 {
            self.dir.join(format!("lr-{lr:e}")).join(format!("seed-{seed}"))
        } else {
            self.dir.join(format!("seed-{seed}"))
        };
        discard_if_stale(&model_dir, &config)?;
        let label = format!("altconv/{scene}/{}/lr-{lr:e}/seed-{seed}", variant.name());
        let mut progress = crate::progress::TrainProgress::new(self.ctx.quiet, &label)?;
        let trained = weft_nn::altconv::train_model(&model_dir, self.dataset, &config, &mut progress)
            .with_context(|| format!("training {label}"))?;
        Ok((trained.state, model_dir))
    }
}

/// Every variant with every seed on `scene` (its directory `base`): the rate chosen on
/// validation with the first seed, the others trained at it; records each variant's
/// training seconds per example and writes its configuration to `base/configs/`.
pub(super) fn train_variants(
    ctx: &EvalContext,
    out: &mut ExperimentOutput,
    scene: &str,
    seeds: &[u64],
    base: &Path,
    dataset: &LimbDataset,
) -> crate::Result<Trained> {
    let rates = learning_rates(ctx.size, scene);
    let mut trained = Trained {
        models: Vec::new(),
        rate_rows: Vec::new(),
        curves: Vec::new(),
    };
    for variant in Variant::ALL {
        let training = VariantTraining {
            ctx,
            scene,
            variant,
            dataset,
            dir: base.join("models").join(variant.name()),
            rates: &rates,
        };
        // The rate: the first seed at each, the best validation score (a single rate is
        // simply trained).
        let study = Study::sweep(
            rates.iter().copied(),
            |&lr| training.train(seeds[0], lr),
            |(state, _)| state.best_validation,
        )?;
        let chosen = *study.chosen();
        let by_rate: Vec<(f64, f64)> = study
            .trials()
            .iter()
            .map(|(lr, (s, _))| (*lr, s.best_validation))
            .collect();
        let (trials, chosen_index) = study.into_parts();
        let mut runs: Vec<_> = trials
            .into_iter()
            .nth(chosen_index)
            .map(|(_, run)| run)
            .into_iter()
            .collect();
        for &seed in &seeds[1..] {
            runs.push(training.train(seed, chosen)?);
        }
        if rates.len() > 1 {
            let mut row = vec![format!("`{}`", variant.name())];
            row.extend(by_rate.iter().map(|(_, v)| format!("{:.2}", 1e3 * v)));
            row.push(format!("{chosen:e}"));
            trained.rate_rows.push(row);
        }
        let mut config = training_config(ctx.size, scene, variant);
        config.adam.learning_rate = chosen;
        let config_path = base.join("configs").join(format!("{}.json", variant.name()));
        std::fs::create_dir_all(config_path.parent().context("config directory")?)?;
        std::fs::write(&config_path, serde_json::to_string_pretty(&config)?)?;
        record_training(out, scene, variant, dataset, &runs);
        trained.curves.push(validation_curve(variant, &runs));
        let mut models: Vec<(f64, PathBuf)> = runs
            .into_iter()
            .map(|(state, dir)| (state.best_validation, dir))
            .collect();
        models.sort_by(|a, b| a.0.total_cmp(&b.0));
        trained.models.push((variant, models));
    }
    Ok(trained)
}

/// Wall time per training sequence pass (forward, backward, Adam), from each run's own
/// record: the fused kernels unless the configuration asks for autograd. The median
/// epoch, so a paused or shared epoch does not move it.
fn record_training(
    out: &mut ExperimentOutput,
    scene: &str,
    variant: Variant,
    dataset: &LimbDataset,
    runs: &[(TrainingState, PathBuf)],
) {
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
    out.split("train");
}

/// The validation curve, mean over the seeds (mm).
fn validation_curve(variant: Variant, runs: &[(TrainingState, PathBuf)]) -> Series {
    let epochs = runs.iter().map(|(s, _)| s.history.len()).min().unwrap_or(0);
    Series {
        label: variant.name().into(),
        x: (1..=epochs).map(|e| e as f64).collect(),
        y: (0..epochs)
            .map(|e| 1e3 * mean_sd(runs.iter().map(|(s, _)| s.history[e].validation)).0)
            .collect(),
    }
}

/// Removes a model directory trained under another configuration than `config` (or
/// whose configuration cannot be read), so that it is retrained rather than refused. A
/// model trained for fewer epochs under the same configuration is kept: the trainer
/// continues it to `config.epochs`, as a straight run would have gone (a larger epoch
/// budget costs only the new epochs).
pub(super) fn discard_if_stale(dir: &Path, config: &AltConvTrainingSettings) -> crate::Result<()> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use weft_data::Size;

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
}
