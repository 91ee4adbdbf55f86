//! The nonlinear inertial correction (weft-nn's `InertialCorrectionMlp`, docs/GUARD.md)
//! in the `guarded` experiment: an MLP on the linear correction's features adding to its
//! codes, trained through the one trainer on the same dataset, for [`SEEDS`]; its one-step
//! M_rms on the test frames (the windows of the linear rows, from the true history) is
//! recorded per seed with their mean and spread, and the seed-0 model joins the dial.
//!
//! Each seed's model is trained afresh in `OUT/guarded/models/sheet-ms-mlp-seed-N` (a run
//! left there by other code or data is not continued).

use std::time::Instant;

use weft_data::ClothDataset;
use weft_nn::inertial_correction_mlp::{InertialCorrectionMlp, InertialCorrectionMlpSettings};

use super::{SCENE, rms};
use crate::evaluate::context::EvalContext;
use crate::records::{ExperimentOutput, SeedFigure, Timing};

/// The method's name in the records.
pub(super) const METHOD: &str = "inertial-correction-mlp";

/// The training seeds (the brief's three).
const SEEDS: [u64; 3] = [0, 1, 2];

/// Trains the model for every seed, records its one-step figure per seed and returns the
/// seed-0 model.
pub(super) fn mlp_rows(
    ctx: &EvalContext,
    out: &mut ExperimentOutput,
    data: &ClothDataset,
) -> crate::Result<InertialCorrectionMlp> {
    let (mut per_seed, mut first) = (Vec::new(), None);
    for seed in SEEDS {
        let dir = ctx
            .out
            .join("guarded")
            .join("models")
            .join(format!("{SCENE}-mlp-seed-{seed}"));
        if dir.exists() {
            std::fs::remove_dir_all(&dir)?;
        }
        let settings = InertialCorrectionMlpSettings {
            seed,
            ..Default::default()
        };
        let clock = Instant::now();
        let (model, state) = InertialCorrectionMlp::train(&dir, data, &settings, &mut weft_nn::trainer::Silent)?;
        let test = rms(&model.one_step_errors(data, "test")?);
        per_seed.push((seed, test));
        let v = model.validation().map_or(String::new(), |v| {
            format!(
                "; validation {:.3} mm (linear {:.3}, inertial {:.3})",
                v.mlp_mm, v.linear_mm, v.predictor_mm
            )
        });
        out.notes.push(format!(
            "guarded: {METHOD} seed {seed} trained in {:.1} s, kept epoch {} of {}{v}; test one-step M_rms {test:.3} mm",
            clock.elapsed().as_secs_f64(),
            state.best_epoch,
            state.epochs_done
        ));
        first.get_or_insert(model);
    }
    let figure = SeedFigure {
        scene: SCENE,
        method: METHOD,
        metric: "one-step-m-rms",
        split: Some("test"),
        unit: "mm",
        timing: Timing::default(),
        paper: None,
    };
    out.record_over_seeds(&figure, &per_seed);
    Ok(first.expect("at least one seed"))
}
