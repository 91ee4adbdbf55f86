//! The drape experiment's data phase: a garment's dataset generated (or resumed) under the
//! evaluation's directory, its splits as tensors, and what every study and score of the
//! garment shares (the configuration, the projection layers, the rest shape).

use std::path::PathBuf;

use weft_data::DrapeDataset;
use weft_data::files::write_json;
use weft_nn::Device;
use weft_nn::drape::{DrapeNetSettings, DrapeTensors, sqrtmse_maxdist_mm};
use weft_nn::drape::{DrapeTrainingSettings, Layers};
use weft_proj::RestShape;

use super::{Garment, SPLITS, TRAIN_SCORED, seeds_of, training_config};
use crate::error::Context;
use crate::evaluate::context::{EvalContext, generate_dataset_frames, ground_truth_seconds};
use crate::records::ExperimentOutput;
use weft_data::Size;

/// One garment's data and what its studies, scoring and tables share.
pub(super) struct GarmentData {
    /// The records' scene name.
    pub scene: &'static str,
    /// `OUT/drape/<garment>/`.
    pub root: PathBuf,
    pub dataset: DrapeDataset,
    pub train: DrapeTensors,
    pub validation: DrapeTensors,
    pub test: DrapeTensors,
    /// The training examples the tables' train columns score ([`TRAIN_SCORED`]).
    pub train_scored: DrapeTensors,
    /// Ground-truth solver seconds per example (the dataset's timing.json).
    pub gt: f64,
    /// Vertices of the sleeve.
    pub v: usize,
    pub seeds: Vec<u64>,
    /// The configuration every model starts from (`root/config.json`).
    pub base: DrapeTrainingSettings,
    pub layers: Layers,
    pub rest: RestShape,
    /// Epochs of the learned global μ from each start (the μ study).
    pub mu_study_epochs: usize,
}

impl GarmentData {
    /// Generates (or resumes) the garment's dataset and loads it; the sequences that stopped
    /// early go to `out`'s failures.
    pub fn load(ctx: &EvalContext, out: &mut ExperimentOutput, garment: &Garment) -> crate::Result<Self> {
        let root = ctx.out.join("drape").join(garment.dir);
        let data_dir = root.join("data");
        let stopped = generate_dataset_frames(ctx, garment.dataset, &data_dir, None)
            .with_context(|| format!("{} dataset", garment.dataset))?;
        out.failures.extend(stopped);
        let gt = ground_truth_seconds(&data_dir)?;
        let dataset = DrapeDataset::load(&data_dir)?;
        let device = Device::Cpu;
        let v = dataset.sleeve.num_vertices();
        let tensors = |s: &str| DrapeTensors::of_split(&dataset, s, &device).with_context(|| format!("the {s} split"));
        let (train, validation, test) = (tensors("train")?, tensors("validation")?, tensors("test")?);
        let train_scored = train.select(&(0..train.len().min(TRAIN_SCORED)).collect::<Vec<_>>())?;
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
        let mu_study_epochs = if ctx.size == Size::Quick {
            base.finetune_epochs
        } else {
            garment.mu_study_epochs
        };
        Ok(Self {
            scene: garment.label,
            root,
            dataset,
            train,
            validation,
            test,
            train_scored,
            gt,
            v,
            seeds: seeds_of(garment, ctx.size),
            base,
            layers,
            rest,
            mu_study_epochs,
        })
    }

    /// The stretch stiffness the energies are measured at (N/m).
    pub fn k(&self) -> f64 {
        self.base.quasistatic.stretch_stiffness
    }

    /// The splits the tables score, by name.
    pub fn scored(&self) -> [(&'static str, &DrapeTensors); 3] {
        [
            ("train", &self.train_scored),
            ("validation", &self.validation),
            ("test", &self.test),
        ]
    }

    /// Where a seed's models are (a single seed keeps the layout without seed directories).
    pub fn models_of(&self, seed: u64) -> PathBuf {
        let models = self.root.join("models");
        if self.seeds.len() > 1 {
            models.join(format!("seed-{seed}"))
        } else {
            models
        }
    }

    /// The base configuration at `seed` and `learning_rate`.
    pub fn config_of(&self, seed: u64, learning_rate: f64) -> DrapeTrainingSettings {
        DrapeTrainingSettings {
            seed,
            learning_rate,
            ..self.base.clone()
        }
    }
}

/// How far the kinematic guess r̃(θ) alone is from the truth on each split: the size of what
/// the network's offsets have to supply, and how much it varies from pose to pose.
pub(super) fn guess_note(scene: &str, dataset: &DrapeDataset) -> crate::Result<String> {
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
