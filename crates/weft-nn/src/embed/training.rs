//! Training Tan et al.'s embedding in three stages (§VI-A) on a pipeline dataset.
//!
//! - Stage 1 trains `E`, `D` with `L₁ = λ_recon L_recon + λ_vert L_vert + λ_ephys L_ephys`.
//! - Stage 2 trains the latent simulator with `L₂ = λ_sim L_sim + λ_mphys L_mphys`, the
//!   autoencoder frozen.
//! - Stage 3 fine-tunes both with `L₃ = λ_recon L_recon + λ_vert L_vert + λ_ephys L_ephys
//!   + λ_sim L_sim`, feeding `z' = ½ z_m + ½ MLP(z_{m−2}, z_{m−1}, q_m)` to `D`.
//!
//! Every physics term goes through the custom ops of [`crate::ops`]: positions are
//! `ACAP⁻¹ ∘ D`, and `L_phys` stops the gradient into its two previous frames (Eq. 9–10).
//! A training window is a frame `m` of the training split whose two predecessors are
//! training frames of the same sequence. Batches are drawn in an order fixed by the seed.

use std::sync::Arc;

use candle_core::{Device, Tensor};
use nalgebra::Vector3;
use weft_acap::{AcapFeatures, AcapSettings, Feature, FeatureNormalization, PoissonPseudoInverse};
use weft_sim::{ClothSimulation, ImplicitEuler};

use super::model::{AutoencoderSettings, LatentSimulator, LatentSimulatorSettings, MeshAutoencoder};
use crate::adam::AdamSettings;
use crate::error::{Error, Result};
use crate::graph::MeshGraph;
use crate::ops::{AcapInverse, LPhys};
use crate::params::ParamStore;
use weft_data::{ClothDataset, is_train_frame, is_validation_frame};

/// Loss weights (Tan et al. Table I: λ_recon = λ_vert = 1, λ_ephys 0.1–1; the "\[46\] +
/// L_vert" baseline sets λ_ephys = 0).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossWeights {
    pub recon: f64,
    pub vert: f64,
    pub ephys: f64,
    pub sim: f64,
    pub mphys: f64,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            recon: 1.0,
            vert: 1.0,
            ephys: 0.5,
            sim: 1.0,
            mphys: 0.5,
        }
    }
}

/// Everything that shapes a training run; stored with the model.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EmbedTrainingSettings {
    pub autoencoder: AutoencoderSettings,
    pub latent_hidden: Vec<usize>,
    pub weights: LossWeights,
    pub adam: AdamSettings,
    /// Windows per batch.
    pub batch: usize,
    /// Epochs (passes over the training windows) of stages 1, 2 and 3.
    pub epochs: [usize; 3],
    pub seed: u64,
    /// How `L_phys` is made commensurate with `L_vert` before its weight applies. A
    /// stored config without the field predates the choice and used
    /// [`PhysScale::Inertial`], so it reads as that and a finished model of it is not
    /// mistaken for one trained with today's default.
    #[serde(default = "PhysScale::legacy")]
    pub phys_scale: PhysScale,
    /// Stage-1 epochs over which λ_ephys ramps linearly from 0 to its value (0: none).
    /// A decoder that does not yet reconstruct gives shapes far from any frame, where a
    /// stiff membrane's `L_phys` outweighs reconstruction by orders of magnitude and
    /// training settles on flat, unstretched shapes instead (docs/EMBEDDING.md). A
    /// stored configuration without the field had no ramp.
    #[serde(default)]
    pub ephys_warmup: usize,
    /// The learning-rate schedule and stopping rules of every stage (constant by
    /// default, as Tan et al., after a [`WARMUP_STEPS`]-batch warm-up at the start of each
    /// stage). A stored configuration without the field, or without its `warmup_steps`,
    /// had no warm-up.
    #[serde(default)]
    pub schedule: crate::trainer::Schedule,
    /// Adam's learning rate in stage 3, which fine-tunes both networks from a fresh
    /// optimiser; `None`: `adam.learning_rate`, as in the other stages. A fresh Adam's
    /// first steps move every weight by about the learning rate whatever its gradient's
    /// size (the moments are empty), and at 10⁻³ stage 3's first epoch raised the
    /// validation loss 4–8-fold (docs/EMBEDDING.md). Only stage 3 reads it: a model
    /// trained under another value keeps stages 1 and 2
    /// ([`EmbedTrainingSettings::stages_continuing_as`]). Not written when `None`, so a
    /// stored configuration from before the field reads as the same.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fine_tune_learning_rate: Option<f64>,
    /// The fused autoencoder ops (default) or candle's autograd, the reference. Not part
    /// of what a resumed run must match.
    #[serde(default)]
    pub kernels: crate::Kernels,
}

/// The factor that multiplies `L_phys` (J) in `L_ephys` and `L_mphys` (m²/J).
///
/// Near a frame, `L_phys ≈ L* + ½ δᵀ H δ` with `H = M/Δt² + K` (`K` the potential's
/// stiffness). `L_vert = ‖δ‖²`, so a scale `s` makes the physics term's curvature `s H`
/// against `L_vert`'s `2I`. Tan et al. tuned λ_ephys per dataset instead; weft fixes the
/// scale from the scene so that one λ_ephys means the same on every scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PhysScale {
    /// `Δt²/m̄`: normalises the inertia only. On a stiff FEM membrane `K ≫ M/Δt²`, the
    /// physics term outweighs reconstruction by the ratio, and training diverges (the
    /// FEM balls, docs/EMBEDDING.md).
    Inertial,
    /// `1 / mean(diag H)` over the free DOFs at the dataset's first frame: the mean
    /// curvature of the whole `L_phys` becomes 1, on soft and stiff scenes alike.
    #[default]
    Curvature,
}

impl EmbedTrainingSettings {
    /// λ_ephys after `progress` and the `fraction` of the current epoch done: ramped over
    /// the first [`EmbedTrainingSettings::ephys_warmup`] epochs of stage 1, constant after.
    pub fn ephys_weight(&self, progress: Progress, fraction: f64) -> f64 {
        if progress.stage != 1 || self.ephys_warmup == 0 {
            return self.weights.ephys;
        }
        let t = (progress.epoch as f64 + fraction.clamp(0.0, 1.0)) / self.ephys_warmup as f64;
        self.weights.ephys * t.min(1.0)
    }

    /// Whether a model trained under `self` is the one `other` would train: the same
    /// configuration, with [`EmbedTrainingSettings::phys_scale`] ignored when both physics
    /// weights are zero (the `no-pb` baseline never evaluates `L_phys`).
    pub fn trains_like(&self, other: &Self) -> bool {
        let other = &Self {
            kernels: self.kernels,
            ..other.clone()
        };
        let physics = |c: &Self| c.weights.ephys != 0.0 || c.weights.mphys != 0.0;
        if physics(self) || physics(other) {
            self == other
        } else {
            Self {
                phys_scale: other.phys_scale,
                ..self.clone()
            } == *other
        }
    }
}

impl EmbedTrainingSettings {
    /// Checks every field before any work: a typed error naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        use crate::trainer::{MAX_BATCH, MAX_EPOCHS, check_adam, check_count, invalid};
        check_count("autoencoder.conv_layers", self.autoencoder.conv_layers, 16)?;
        check_count("autoencoder.latent", self.autoencoder.latent, 65_536)?;
        check_count("latent_hidden (number of layers)", self.latent_hidden.len().max(1), 64)?;
        for (i, &w) in self.latent_hidden.iter().enumerate() {
            check_count(&format!("latent_hidden[{i}]"), w, 65_536)?;
        }
        for (name, w) in [
            ("weights.recon", self.weights.recon),
            ("weights.vert", self.weights.vert),
            ("weights.ephys", self.weights.ephys),
            ("weights.sim", self.weights.sim),
            ("weights.mphys", self.weights.mphys),
        ] {
            if !(w >= 0.0 && w.is_finite()) {
                return Err(invalid(name, w, "must be non-negative and finite"));
            }
        }
        check_adam("adam", &self.adam)?;
        if let Some(lr) = self.fine_tune_learning_rate {
            crate::trainer::check_learning_rate("fine_tune_learning_rate", lr)?;
        }
        check_count("batch", self.batch, MAX_BATCH)?;
        for (i, &e) in self.epochs.iter().enumerate() {
            if e > MAX_EPOCHS {
                return Err(invalid(&format!("epochs[{i}]"), e, "is beyond any sensible size"));
            }
        }
        if self.ephys_warmup > MAX_EPOCHS {
            return Err(invalid(
                "ephys_warmup",
                self.ephys_warmup,
                "is beyond any sensible size",
            ));
        }
        self.schedule.validate("schedule")
    }

    /// The trainer's configuration of `stage` (1, 2 or 3).
    /// Whether a model trained under `self` can be continued under `other`: it
    /// [trains like](Self::trains_like) `other` but for the stages' epoch counts and the
    /// early-stopping patience, within what every stage's trainer accepts
    /// ([`crate::trainer::TrainerSettings::continues_as`]: the patience may only grow).
    pub fn continues_as(&self, other: &Self) -> bool {
        let mut same = Self {
            epochs: other.epochs,
            ..self.clone()
        };
        same.schedule.early_stopping_patience = other.schedule.early_stopping_patience;
        (1..=3u8).all(|s| self.trainer(s).continues_as(&other.trainer(s))) && same.trains_like(other)
    }

    /// How many leading stages of a model trained under `self` continue under `other`:
    /// 3 when it [continues as](Self::continues_as) `other`; 2 when they differ only in
    /// what stage 3 alone reads ([`EmbedTrainingSettings::fine_tune_learning_rate`]), stage 3
    /// then training afresh from stage 2's weights; 0 otherwise.
    pub fn stages_continuing_as(&self, other: &Self) -> u8 {
        if self.continues_as(other) {
            return 3;
        }
        let but_stage_3 = Self {
            fine_tune_learning_rate: other.fine_tune_learning_rate,
            ..self.clone()
        };
        if but_stage_3.continues_as(other) { 2 } else { 0 }
    }

    /// Adam's settings in `stage`: [`EmbedTrainingSettings::adam`], with stage 3's learning
    /// rate [`EmbedTrainingSettings::fine_tune_learning_rate`] when set.
    pub fn stage_adam(&self, stage: u8) -> AdamSettings {
        match (stage, self.fine_tune_learning_rate) {
            (3, Some(learning_rate)) => AdamSettings {
                learning_rate,
                ..self.adam
            },
            _ => self.adam,
        }
    }

    pub fn trainer(&self, stage: u8) -> crate::trainer::TrainerSettings {
        crate::trainer::TrainerSettings {
            epochs: self.epochs[stage as usize - 1],
            batch: self.batch,
            seed: self.seed,
            schedule: self.schedule,
        }
    }
}

impl PhysScale {
    fn legacy() -> Self {
        PhysScale::Inertial
    }
}

/// Batches over which each stage's learning rate ramps up ([`Schedule::warmup_steps`]).
///
/// Why: without it, Adam's first step moves the encoder's fully connected layer, which sums
/// every vertex's activations (38 025 on the standard sheet, mostly of one sign), by about
/// `lr · Σ|h|`: on `sheet-ms` seed 1's mean |code| is 14 after one step and 66 after 25,
/// the decoder's `tanh` saturates, and depending on the seed stage 1 then sits on a plateau
/// for 10 to more than 40 epochs, or stops there early; one seed in three of the standard
/// run did. With a 50-batch ramp (a standard epoch is 40) the code stays below about 1 and
/// the seeds tried are all past the plateau by the fifth epoch (docs/EMBEDDING.md, "Adam's
/// first steps"; `cargo run --example embed_first_steps`).
///
/// [`Schedule::warmup_steps`]: crate::trainer::Schedule::warmup_steps
pub const WARMUP_STEPS: usize = 50;

impl Default for EmbedTrainingSettings {
    fn default() -> Self {
        Self {
            autoencoder: AutoencoderSettings::default(),
            latent_hidden: vec![256, 256],
            weights: LossWeights::default(),
            adam: AdamSettings::default(),
            batch: 8,
            epochs: [30, 30, 10],
            seed: 0,
            phys_scale: PhysScale::default(),
            ephys_warmup: 0,
            schedule: crate::trainer::Schedule {
                warmup_steps: WARMUP_STEPS,
                ..crate::trainer::Schedule::default()
            },
            fine_tune_learning_rate: None,
            kernels: crate::Kernels::default(),
        }
    }
}

/// A frame of the dataset: sequence and frame index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRef {
    pub sequence: usize,
    pub frame: usize,
}

/// The loss terms of one evaluation (unweighted means over the batch).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct LossTerms {
    pub recon: f64,
    pub vert: f64,
    pub ephys: f64,
    pub sim: f64,
    pub mphys: f64,
    pub total: f64,
}

/// A dataset prepared for the embedding: normalised ACAP features of every frame, the
/// pseudo-inverse pinned at the grasped vertices, and the integrator of `L_phys`.
#[derive(Debug)]
pub struct EmbedData {
    pub dataset: ClothDataset,
    pub normalization: FeatureNormalization,
    /// `features[s][m]`: normalised features of frame `m` of sequence `s`.
    features: Vec<Vec<Vec<Feature>>>,
    /// The ACAP feature extractor of the rest mesh: how frames given as positions are
    /// encoded ([`sequence_features`]).
    pub acap: Arc<AcapFeatures>,
    pub inverse: Arc<PoissonPseudoInverse>,
    pub integrator: Arc<ImplicitEuler>,
    /// `Δt² / m̄` (m²/J, `m̄` the mean vertex mass): [`PhysScale::Inertial`].
    pub inertial_scale: f64,
    /// `1 / mean(diag ∂²L_phys/∂p²)` over the free DOFs at the first frame of the first
    /// sequence, held still (m²/J): [`PhysScale::Curvature`].
    pub curvature_scale: f64,
    /// Training windows (frame `m` and both predecessors training frames, `m` not a
    /// validation frame; [`weft_data::is_validation_frame`]).
    pub train_windows: Vec<FrameRef>,
    /// Validation windows: frame `m` a validation frame, its predecessors in Tan et al.'s
    /// training frames. Model selection reads these only.
    pub validation_windows: Vec<FrameRef>,
    /// Every test frame (the last 5 of each 17), in sequence order.
    pub test_frames: Vec<FrameRef>,
}

fn points(x: &[f64]) -> Vec<Vector3<f64>> {
    x.chunks_exact(3).map(|c| Vector3::new(c[0], c[1], c[2])).collect()
}

/// The ACAP features (not normalised) of consecutive frames of one sequence (flat
/// positions, m), encoded in order so the log-rotations stay continuous in time
/// ([`AcapFeatures::encode_sequence`]): how [`EmbedData`] encodes a dataset's sequences,
/// and how frames given as positions (the guard's accepted frames) are encoded.
pub fn sequence_features<P: AsRef<[f64]>>(acap: &AcapFeatures, frames: &[P]) -> Result<Vec<Vec<Feature>>> {
    let frames: Vec<Vec<Vector3<f64>>> = frames.iter().map(|p| points(p.as_ref())).collect();
    Ok(acap.encode_sequence(&frames)?)
}

/// `[B, V, 9]` f32 tensor of `B` frames' (normalised) features.
fn features_tensor<'f>(
    frames: impl ExactSizeIterator<Item = &'f [Feature]>,
    v: usize,
    device: &Device,
) -> Result<Tensor> {
    let b = frames.len();
    let flat: Vec<f32> = frames
        .flat_map(|f| f.iter().flat_map(|x| x.map(|c| c as f32)))
        .collect();
    Ok(Tensor::from_vec(flat, (b, v, 9), device)?)
}

impl EmbedData {
    /// Encodes every frame (as a sequence, so log-rotations stay continuous in time) and
    /// fits the normalisation on the training frames only.
    pub fn new(dataset: ClothDataset) -> Result<Self> {
        Self::build(dataset, None)
    }

    /// The dataset prepared for a trained model: its features normalised by the model's
    /// own normalisation (`normalization.json`), not one refitted on this dataset — how a
    /// model is scored on data it never saw.
    pub fn with_normalization(dataset: ClothDataset, normalization: FeatureNormalization) -> Result<Self> {
        Self::build(dataset, Some(normalization))
    }

    fn build(dataset: ClothDataset, normalization: Option<FeatureNormalization>) -> Result<Self> {
        let acap = AcapFeatures::new(&dataset.rest, AcapSettings::default())?;
        let raw: Vec<Vec<Vec<Feature>>> = dataset
            .sequences
            .iter()
            .map(|s| sequence_features(&acap, &(0..s.num_frames()).map(|m| s.frame(m)).collect::<Vec<_>>()))
            .collect::<Result<_>>()?;
        let normalization = match normalization {
            Some(n) => n,
            None => FeatureNormalization::fit_per_block(raw.iter().flat_map(|seq| {
                seq.iter()
                    .enumerate()
                    .filter(|(m, _)| is_train_frame(*m) && !is_validation_frame(*m))
                    .flat_map(|(_, f)| f)
            }))?,
        };
        let features = raw
            .iter()
            .map(|seq| seq.iter().map(|f| normalization.normalize_all(f)).collect())
            .collect();
        let inverse = Arc::new(PoissonPseudoInverse::new(&acap, &dataset.grasp)?);
        let integrator = Arc::new(ClothSimulation::new(dataset.scene.clone(), Some(&dataset.dir))?.into_integrator());
        let masses = integrator.masses();
        let mean_mass = masses.iter().sum::<f64>() / masses.len().max(1) as f64;
        let inertial_scale = integrator.dt().powi(2) / mean_mass;
        let curvature_scale = {
            let first = dataset.sequences.first().ok_or_else(|| Error::InvalidParameter {
                name: "dataset",
                value: dataset.name.clone(),
                reason: "has no sequence",
            })?;
            let p = first.frame(0);
            let diag = integrator.l_phys_hessian_diagonal(p, p, p)?;
            let free: Vec<f64> = diag
                .iter()
                .zip(integrator.fixed())
                .filter(|(_, f)| !**f)
                .map(|(d, _)| *d)
                .collect();
            let mean = free.iter().sum::<f64>() / free.len().max(1) as f64;
            if !(mean.is_finite() && mean > 0.0) {
                return Err(Error::InvalidParameter {
                    name: "dataset",
                    value: dataset.name.clone(),
                    reason: "L_phys has no positive curvature at its first frame",
                });
            }
            1.0 / mean
        };
        let mut train_windows = Vec::new();
        let mut validation_windows = Vec::new();
        let mut test_frames = Vec::new();
        for (s, seq) in dataset.sequences.iter().enumerate() {
            for m in 2..seq.num_frames() {
                if is_train_frame(m) && is_train_frame(m - 1) && is_train_frame(m - 2) {
                    if is_validation_frame(m) {
                        validation_windows.push(FrameRef { sequence: s, frame: m });
                    } else {
                        train_windows.push(FrameRef { sequence: s, frame: m });
                    }
                } else if !is_train_frame(m) {
                    test_frames.push(FrameRef { sequence: s, frame: m });
                }
            }
        }
        if train_windows.is_empty() {
            return Err(Error::InvalidParameter {
                name: "dataset",
                value: dataset.name.clone(),
                reason: "has no training window (needs sequences of at least 3 frames)",
            });
        }
        Ok(Self {
            dataset,
            normalization,
            features,
            acap: Arc::new(acap),
            inverse,
            integrator,
            inertial_scale,
            curvature_scale,
            train_windows,
            validation_windows,
            test_frames,
        })
    }

    pub fn num_vertices(&self) -> usize {
        self.dataset.rest.num_vertices()
    }

    /// The factor on `L_phys` in the losses (m²/J).
    pub fn phys_scale(&self, kind: PhysScale) -> f64 {
        match kind {
            PhysScale::Inertial => self.inertial_scale,
            PhysScale::Curvature => self.curvature_scale,
        }
    }

    /// `[B, V, 9]` normalised features of `frames`.
    pub fn feature_batch(&self, frames: &[FrameRef], device: &Device) -> Result<Tensor> {
        let rows = frames.iter().map(|f| self.features[f.sequence][f.frame].as_slice());
        features_tensor(rows, self.num_vertices(), device)
    }

    /// The f32 tensor of shape `[B, shape…]` stacking `values(sequence, frame)` of `frames`.
    fn stack(
        &self,
        frames: &[FrameRef],
        shape: &[usize],
        device: &Device,
        values: impl Fn(&weft_data::ClothSequence, usize) -> &[f64],
    ) -> Result<Tensor> {
        let flat: Vec<f32> = frames
            .iter()
            .flat_map(|f| {
                values(&self.dataset.sequences[f.sequence], f.frame)
                    .iter()
                    .map(|&x| x as f32)
            })
            .collect();
        let mut dims = vec![frames.len()];
        dims.extend(shape);
        Ok(Tensor::from_vec(flat, dims, device)?)
    }

    /// `[B, V, 3]` ground-truth positions of `frames`.
    pub fn position_batch(&self, frames: &[FrameRef], device: &Device) -> Result<Tensor> {
        self.stack(frames, &[self.num_vertices(), 3], device, |s, m| s.frame(m))
    }

    /// `[B, 3G]` controls `q_m` of `frames`.
    pub fn control_batch(&self, frames: &[FrameRef], device: &Device) -> Result<Tensor> {
        self.stack(frames, &[3 * self.dataset.grasp.len()], device, |s, m| s.control(m))
    }

    /// ACAP⁻¹ for `frames`, pinned at their grasped positions.
    pub fn decoder_op(&self, frames: &[FrameRef]) -> AcapInverse {
        let pins = frames
            .iter()
            .map(|f| {
                let q = self.dataset.sequences[f.sequence].control(f.frame);
                points(q)
            })
            .collect();
        AcapInverse::new(self.inverse.clone(), self.normalization.clone(), pins)
    }

    pub fn lphys_op(&self) -> LPhys {
        LPhys::new(self.integrator.clone())
    }
}

/// The embedding's two networks with their parameters and optimisers.
#[derive(Debug)]
pub struct EmbedModel {
    pub config: EmbedTrainingSettings,
    pub autoencoder_params: ParamStore,
    pub autoencoder: MeshAutoencoder,
    pub simulator_params: ParamStore,
    pub simulator: LatentSimulator,
}

impl EmbedModel {
    /// The two networks, initialised from `config.seed`, on the CPU.
    pub fn new(config: EmbedTrainingSettings, data: &EmbedData) -> Result<Self> {
        let device = &Device::Cpu;
        let graph = Arc::new(MeshGraph::new(&data.dataset.rest, device)?);
        let mut autoencoder_params = ParamStore::new(device, config.seed);
        let autoencoder =
            MeshAutoencoder::new(&mut autoencoder_params, graph, config.autoencoder)?.with_kernels(config.kernels);
        let mut simulator_params = ParamStore::new(device, config.seed ^ 0x5151_5151);
        let simulator = LatentSimulator::new(
            &mut simulator_params,
            LatentSimulatorSettings {
                latent: config.autoencoder.latent,
                controls: 3 * data.dataset.grasp.len(),
                hidden: config.latent_hidden.clone(),
            },
        )?;
        Ok(Self {
            config,
            autoencoder_params,
            autoencoder,
            simulator_params,
            simulator,
        })
    }

    /// A trained model from a model directory written by [`train_stages`] (`cargo xtask
    /// train embed`): `config.json` and each stage's best weights, up to and including
    /// stage `after` (Tan Table IV reads the model after stage 2 and after stage 3).
    pub fn load(dir: &std::path::Path, data: &EmbedData, after: u8) -> Result<Self> {
        crate::checkpoint::check_model_kind(dir, "embed")?;
        let path = dir.join("config.json");
        let text = std::fs::read_to_string(&path).map_err(|source| Error::Io {
            path: path.display().to_string(),
            source,
        })?;
        let config: EmbedTrainingSettings = serde_json::from_str(&text).map_err(|e| Error::Checkpoint {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        let model = Self::new(config, data)?;
        let mut any = false;
        for stage in 1..=after.min(3) {
            let run = stage_dir(dir, stage);
            if crate::trainer::has_run(&run) {
                crate::trainer::load_weights(&run.join("best"), &model.stage_groups(stage))?;
                any = true;
            }
        }
        if !any {
            return Err(Error::Checkpoint {
                path: dir.display().to_string(),
                reason: format!("no trained stage up to stage {after}"),
            });
        }
        Ok(model)
    }

    /// The parameter groups stage `stage` trains: the autoencoder (1), the latent
    /// simulator (2), both (3).
    pub fn stage_groups(&self, stage: u8) -> Vec<crate::trainer::Group<'_>> {
        let adam = self.config.stage_adam(stage);
        let ae = crate::trainer::Group {
            name: "autoencoder",
            params: &self.autoencoder_params,
            adam,
        };
        let sim = crate::trainer::Group {
            name: "simulator",
            params: &self.simulator_params,
            adam,
        };
        match stage {
            1 => vec![ae],
            2 => vec![sim],
            _ => vec![ae, sim],
        }
    }

    /// `ACAP⁻¹ ∘ D ∘ E` of `frames`, in batches of `batch`: the reconstructed positions
    /// (flat, metres), one per frame.
    pub fn reconstruct(&self, data: &EmbedData, frames: &[FrameRef], batch: usize) -> Result<Vec<Vec<f64>>> {
        let device = self.autoencoder_params.device();
        let mut out = Vec::with_capacity(frames.len());
        for chunk in frames.chunks(batch.max(1)) {
            let z = self.autoencoder.encode(&data.feature_batch(chunk, device)?)?;
            let p = self.positions(data, chunk, &z)?;
            let flat = crate::convert::tensor_to_f64("reconstructed positions", &p)?;
            out.extend(flat.chunks_exact(3 * data.num_vertices()).map(<[f64]>::to_vec));
        }
        Ok(out)
    }

    /// Latent codes `E(x)` of `frames` (flat `latent` values per frame).
    pub fn codes(&self, data: &EmbedData, frames: &[FrameRef]) -> Result<Vec<Vec<f64>>> {
        self.codes_of(&data.feature_batch(frames, self.autoencoder_params.device())?)
    }

    /// Latent codes `E(x)` of frames given by their normalised features (flat `latent`
    /// values per frame): [`EmbedModel::codes`] of frames that are not the dataset's.
    pub fn codes_of_features(&self, features: &[Vec<Feature>]) -> Result<Vec<Vec<f64>>> {
        let v = features.first().map_or(0, Vec::len);
        let rows = features.iter().map(Vec::as_slice);
        self.codes_of(&features_tensor(rows, v, self.autoencoder_params.device())?)
    }

    fn codes_of(&self, x: &Tensor) -> Result<Vec<Vec<f64>>> {
        let z = self.autoencoder.encode(x)?;
        let flat = crate::convert::tensor_to_f64("latent codes", &z)?;
        Ok(flat
            .chunks_exact(self.config.autoencoder.latent)
            .map(<[f64]>::to_vec)
            .collect())
    }

    /// Decoded positions `[B, V, 3]` of codes `z` for `frames` (pinned at their controls).
    pub fn positions(&self, data: &EmbedData, frames: &[FrameRef], z: &Tensor) -> Result<Tensor> {
        data.decoder_op(frames).apply(&self.autoencoder.decode(z)?)
    }

    /// The losses of `stage` (1, 2 or 3) on the windows `batch` (frames `m`), as a graph
    /// whose `total` can be differentiated, plus their values.
    /// The losses of `stage` on `batch`, with λ_ephys = `ephys` (see
    /// [`EmbedTrainingSettings::ephys_weight`]); the other weights are the configuration's.
    pub fn losses(&self, data: &EmbedData, batch: &[FrameRef], stage: u8, ephys: f64) -> Result<(Tensor, LossTerms)> {
        self.losses_with(data, batch, stage, ephys, None)
    }

    /// [`EmbedModel::losses`], with stage 2's frozen codes and predecessor positions
    /// read from `frozen` instead of recomputed (the same values: the autoencoder does
    /// not change in stage 2).
    fn losses_with(
        &self,
        data: &EmbedData,
        batch: &[FrameRef],
        stage: u8,
        ephys: f64,
        frozen: Option<&FrozenAutoencoder>,
    ) -> Result<(Tensor, LossTerms)> {
        let w = LossWeights {
            ephys,
            ..self.config.weights
        };
        let (total, terms, _) = self.loss_graph(data, batch, stage, w, frozen)?;
        Ok((total, terms))
    }

    /// The losses of `stage` on `batch` under the weights `w`: the weighted total as a
    /// graph, the terms' values, and each term evaluated (unweighted, as a graph of its
    /// own) — [`super::decoder_gradient_norms`] differentiates them one at a time. A term
    /// whose weight is 0 is left out of the total, and `L_ephys` / `L_mphys` are not
    /// evaluated at all (the `no-pb` baseline never calls `L_phys`).
    pub(super) fn loss_graph(
        &self,
        data: &EmbedData,
        batch: &[FrameRef],
        stage: u8,
        w: LossWeights,
        frozen: Option<&FrozenAutoencoder>,
    ) -> Result<(Tensor, LossTerms, Vec<(&'static str, Tensor)>)> {
        let device = self.autoencoder_params.device();
        let (b1, b2) = (predecessors(batch, 1), predecessors(batch, 2));
        let scalar = |t: &Tensor| -> Result<f64> { Ok(t.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>()?) };
        let mut terms = LossTerms::default();
        let mut total = Tensor::zeros((), candle_core::DType::F32, device)?;
        let mut graphs = Vec::new();
        let mut add = |name: &'static str, t: Tensor, weight: f64, slot: &mut f64| -> Result<()> {
            *slot = scalar(&t)?;
            if weight != 0.0 {
                total = (&total + (&t * weight)?)?;
            }
            graphs.push((name, t));
            Ok(())
        };
        let lphys = data.lphys_op();
        let phys_scale = data.phys_scale(self.config.phys_scale);
        if stage == 1 || stage == 3 {
            let x = data.feature_batch(batch, device)?;
            // The predecessors' codes feed the latent step (stage 3) and L_ephys; the
            // baseline in stage 1 needs neither. The window's frame and its predecessors
            // go through each network as one batch (`MeshAutoencoder::encode_all`).
            let (z, predecessors) = if stage == 3 || w.ephys != 0.0 {
                let (x1, x2) = (data.feature_batch(&b1, device)?, data.feature_batch(&b2, device)?);
                let [z, z1, z2] = three(self.autoencoder.encode_all(&[&x, &x1, &x2])?)?;
                (z, Some((z1, z2)))
            } else {
                (self.autoencoder.encode(&x)?, None)
            };
            let z_used = if let (3, Some((z1, z2))) = (stage, &predecessors) {
                let q = data.control_batch(batch, device)?;
                let predicted = self.simulator.step(z2, z1, &q)?;
                let sim = (&predicted - &z)?.sqr()?.sum(1)?.mean_all()?;
                add("sim", sim, w.sim, &mut terms.sim)?;
                ((&z * 0.5)? + (predicted * 0.5)?)?
            } else {
                z.clone()
            };
            // L_ephys decodes the predecessors too: with the window's code, one batch.
            let (y, decoded) = match (w.ephys != 0.0, &predecessors) {
                (true, Some((z1, z2))) => {
                    let [y, y1, y2] = three(self.autoencoder.decode_all(&[&z_used, z1, z2])?)?;
                    (y, Some((y1, y2)))
                }
                _ => (self.autoencoder.decode(&z_used)?, None),
            };
            let recon = (&y - &x)?.sqr()?.sum((1, 2))?.mean_all()?;
            add("recon", recon, w.recon, &mut terms.recon)?;
            let p = data.decoder_op(batch).apply(&y)?;
            let truth = data.position_batch(batch, device)?;
            let vert = (&p - &truth)?.sqr()?.sum((1, 2))?.mean_all()?;
            add("vert", vert, w.vert, &mut terms.vert)?;
            if let Some((y1, y2)) = decoded {
                let p1 = data.decoder_op(&b1).apply(&y1)?;
                let p2 = data.decoder_op(&b2).apply(&y2)?;
                let ephys = (lphys.apply(&p2, &p1, &p)?.mean_all()? * phys_scale)?;
                add("ephys", ephys, w.ephys, &mut terms.ephys)?;
            }
        } else {
            // Stage 2: the autoencoder is frozen (its codes are detached).
            let code = |frames: &[FrameRef]| -> Result<Tensor> {
                match frozen {
                    Some(f) => f.codes(frames),
                    None => Ok(self.autoencoder.encode(&data.feature_batch(frames, device)?)?.detach()),
                }
            };
            let (z, z1, z2) = (code(batch)?, code(&b1)?, code(&b2)?);
            let q = data.control_batch(batch, device)?;
            let predicted = self.simulator.step(&z2, &z1, &q)?;
            let sim = (&predicted - &z)?.sqr()?.sum(1)?.mean_all()?;
            add("sim", sim, w.sim, &mut terms.sim)?;
            if w.mphys != 0.0 {
                let p = self.positions(data, batch, &predicted)?;
                // The predecessors' positions carry no gradient to the simulator.
                let decoded = |frames: &[FrameRef], z: &Tensor| -> Result<Tensor> {
                    match frozen.and_then(|f| f.positions(frames)) {
                        Some(p) => p,
                        None => self.positions(data, frames, z),
                    }
                };
                let (p1, p2) = (decoded(&b1, &z1)?, decoded(&b2, &z2)?);
                let mphys = (lphys.apply(&p2, &p1, &p)?.mean_all()? * phys_scale)?;
                add("mphys", mphys, w.mphys, &mut terms.mphys)?;
            }
        }
        terms.total = scalar(&total)?;
        Ok((total, terms, graphs))
    }
}

/// The three batches [`MeshAutoencoder::encode_all`] / `decode_all` return for three.
fn three(parts: Vec<Tensor>) -> Result<[Tensor; 3]> {
    <[Tensor; 3]>::try_from(parts).map_err(|parts| Error::Shape {
        what: "autoencoder batches",
        expected: "3".into(),
        got: parts.len().to_string(),
    })
}

/// The windows' frames `k` steps back.
fn predecessors(batch: &[FrameRef], k: usize) -> Vec<FrameRef> {
    batch
        .iter()
        .map(|f| FrameRef {
            sequence: f.sequence,
            frame: f.frame - k,
        })
        .collect()
}

/// Stage 2's autoencoder, evaluated once for every frame the stage reads: the codes
/// `E(x)` and, when `L_mphys` is on, the positions `ACAP⁻¹ ∘ D ∘ E(x)` (the predecessors'
/// in `L_mphys`). Stage 2 trains the latent simulator only, so these are constants of the
/// stage; recomputing them per batch was most of a stage-2 step.
#[derive(Debug)]
pub(super) struct FrozenAutoencoder {
    codes: std::collections::HashMap<(usize, usize), Tensor>,
    positions: std::collections::HashMap<(usize, usize), Tensor>,
}

impl FrozenAutoencoder {
    /// Evaluates `model`'s autoencoder on every frame of `windows` and its two predecessors,
    /// in batches of the configuration's size.
    fn new(model: &EmbedModel, data: &EmbedData, windows: &[FrameRef]) -> Result<Self> {
        let mut frames: Vec<FrameRef> = (0..3).flat_map(|k| predecessors(windows, k)).collect();
        frames.sort_by_key(|f| (f.sequence, f.frame));
        frames.dedup();
        let device = model.autoencoder_params.device();
        let mut codes = std::collections::HashMap::new();
        let mut positions = std::collections::HashMap::new();
        for chunk in frames.chunks(model.config.batch.max(1)) {
            let z = model.autoencoder.encode(&data.feature_batch(chunk, device)?)?.detach();
            let p = if model.config.weights.mphys != 0.0 {
                Some(model.positions(data, chunk, &z)?.detach())
            } else {
                None
            };
            for (i, f) in chunk.iter().enumerate() {
                codes.insert((f.sequence, f.frame), z.get(i)?);
                if let Some(p) = &p {
                    positions.insert((f.sequence, f.frame), p.get(i)?);
                }
            }
        }
        Ok(Self { codes, positions })
    }

    fn lookup(map: &std::collections::HashMap<(usize, usize), Tensor>, frames: &[FrameRef]) -> Option<Result<Tensor>> {
        let rows: Option<Vec<&Tensor>> = frames.iter().map(|f| map.get(&(f.sequence, f.frame))).collect();
        rows.map(|rows| Ok(Tensor::stack(&rows, 0)?))
    }

    /// `[B, latent]` codes of `frames`.
    fn codes(&self, frames: &[FrameRef]) -> Result<Tensor> {
        Self::lookup(&self.codes, frames).unwrap_or_else(|| {
            Err(Error::InvalidParameter {
                name: "frozen codes",
                value: format!("{frames:?}"),
                reason: "a frame outside the stage's windows",
            })
        })
    }

    /// `[B, V, 3]` decoded positions of `frames`, if `L_mphys` is on and all were evaluated.
    fn positions(&self, frames: &[FrameRef]) -> Option<Result<Tensor>> {
        Self::lookup(&self.positions, frames)
    }
}

/// One stage of the embedding as the [`crate::trainer::Trainer`] sees it: examples are
/// the training windows, the loss is the stage's (λ_ephys ramped as configured), the
/// validation score the stage's total loss on the validation windows at the full weights.
#[derive(Debug)]
pub struct EmbedStage<'a> {
    pub model: &'a EmbedModel,
    pub data: &'a EmbedData,
    /// 1, 2 or 3.
    pub stage: u8,
    /// Stage 2's frozen autoencoder outputs, evaluated on first use.
    frozen: Option<FrozenAutoencoder>,
}

impl<'a> EmbedStage<'a> {
    pub fn new(model: &'a EmbedModel, data: &'a EmbedData, stage: u8) -> Self {
        Self {
            model,
            data,
            stage,
            frozen: None,
        }
    }

    /// The stage's losses on `frames`; stage 2 reads the frozen autoencoder's outputs,
    /// evaluated once on every training and validation window.
    fn losses(&mut self, frames: &[FrameRef], ephys: f64) -> Result<(Tensor, LossTerms)> {
        if self.stage == 2 && self.frozen.is_none() {
            let windows: Vec<FrameRef> = self
                .data
                .train_windows
                .iter()
                .chain(&self.data.validation_windows)
                .copied()
                .collect();
            self.frozen = Some(FrozenAutoencoder::new(self.model, self.data, &windows)?);
        }
        let frozen = if self.stage == 2 { self.frozen.as_ref() } else { None };
        self.model.losses_with(self.data, frames, self.stage, ephys, frozen)
    }
}

impl crate::trainer::Trainable for EmbedStage<'_> {
    fn groups(&self) -> Vec<crate::trainer::Group<'_>> {
        self.model.stage_groups(self.stage)
    }

    fn num_examples(&self) -> usize {
        self.data.train_windows.len()
    }

    fn batch_loss(&mut self, batch: &[usize], at: crate::trainer::BatchAt) -> Result<crate::trainer::BatchLoss> {
        let frames: Vec<FrameRef> = batch.iter().map(|&i| self.data.train_windows[i]).collect();
        let progress = Progress {
            stage: self.stage,
            epoch: at.epoch,
        };
        let ephys = self
            .model
            .config
            .ephys_weight(progress, at.batch as f64 / at.batches as f64);
        let (loss, t) = self.losses(&frames, ephys)?;
        Ok(crate::trainer::BatchLoss::Loss {
            loss,
            terms: vec![
                ("recon", t.recon),
                ("vert", t.vert),
                ("ephys", t.ephys),
                ("sim", t.sim),
                ("mphys", t.mphys),
            ],
        })
    }

    fn validation_score(&mut self) -> Result<f64> {
        let data = self.data;
        let windows = &data.validation_windows;
        if windows.is_empty() {
            return Err(Error::InvalidParameter {
                name: "validation split",
                value: "0 windows".into(),
                reason: "model selection needs validation windows (sequences of at least 12 frames)",
            });
        }
        let mut sum = 0.0;
        let ephys = self.model.config.weights.ephys;
        for chunk in windows.chunks(self.model.config.batch.max(1)) {
            let (_, t) = self.losses(chunk, ephys)?;
            sum += t.total * chunk.len() as f64;
        }
        Ok(sum / windows.len() as f64)
    }

    /// The order of stage `s`, epoch `e`: SplitMix64(seed ⊕ s·2⁵⁶ ⊕ e·0x9E3779B9), as
    /// before the trainer.
    fn shuffle_seed(&self, seed: u64, epoch: usize) -> u64 {
        seed ^ ((self.stage as u64) << 56) ^ (epoch as u64).wrapping_mul(0x9E37_79B9)
    }
}

/// Where a run stands in the three stages (λ_ephys's ramp reads it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Progress {
    /// 1, 2 or 3.
    pub stage: u8,
    /// Epochs completed in this stage.
    pub epoch: usize,
}

/// The trainer's run directory of stage `stage` in a model directory.
pub fn stage_dir(dir: &std::path::Path, stage: u8) -> std::path::PathBuf {
    dir.join(format!("stage-{stage}"))
}

/// Whether stage `stage` of the model in `dir` is complete under `config` (all its epochs
/// trained, or stopped by `config`'s early stopping).
pub fn stage_done(dir: &std::path::Path, stage: u8, config: &crate::trainer::TrainerSettings) -> bool {
    crate::trainer::TrainingState::read(&stage_dir(dir, stage)).is_ok_and(|s| s.finished_under(config))
}

/// Whether training the model in `dir` on under `config` gives exactly the model a fresh
/// directory would: it was trained under a configuration whose leading stages
/// [continue](EmbedTrainingSettings::stages_continuing_as) under `config` (the others are
/// trained afresh by [`train_model`]), none of those stages has trained more epochs than
/// `config` allows it, and each of them that trained still has its weights. `false` when
/// `dir` holds no model.
pub fn continues_exactly(dir: &std::path::Path, config: &EmbedTrainingSettings) -> bool {
    let Ok(have) = crate::checkpoint::read_json::<EmbedTrainingSettings>(&dir.join("config.json")) else {
        return false;
    };
    let kept = have.stages_continuing_as(config);
    kept > 0
        && (1..=kept).all(|stage| {
            let run = stage_dir(dir, stage);
            !crate::trainer::has_run(&run)
                || crate::trainer::TrainingState::read(&run)
                    .is_ok_and(|s| s.continues_exactly_as(&config.trainer(stage)))
                    && crate::trainer::has_checkpoints(&run)
        })
}

/// Trains `stages` (ascending) of `model` in the model directory `dir`, one trainer run
/// per stage (`stage-1/`, `stage-2/`, `stage-3/`), resuming where a run stopped. A stage
/// already complete is loaded at its best weights instead; a stage of 0 epochs is skipped.
/// A stage that trains on (more epochs, a longer patience) discards the later stages'
/// runs: they started from its old weights.
/// Every stage's Adam starts afresh (each is a new objective). Returns each trained
/// stage's state.
pub fn train_stages(
    dir: &std::path::Path,
    model: &EmbedModel,
    data: &EmbedData,
    stages: &[u8],
    label: &str,
    observer: &mut dyn crate::trainer::Observer,
) -> Result<Vec<(u8, crate::trainer::TrainingState)>> {
    model.config.validate()?;
    check_stages(dir, &model.config, stages)?;
    // Stages before the first asked for (`--stages 2,3` continues a trained autoencoder)
    // are loaded at their best weights.
    for earlier in 1..stages.iter().copied().min().unwrap_or(1) {
        let run = stage_dir(dir, earlier);
        if crate::trainer::has_run(&run) {
            crate::trainer::load_weights(&run.join("best"), &model.stage_groups(earlier))?;
        }
    }
    let mut out = Vec::new();
    for &stage in stages {
        let config = model.config.trainer(stage);
        if config.epochs == 0 {
            continue;
        }
        let run = stage_dir(dir, stage);
        let state = if stage_done(dir, stage, &config) {
            crate::trainer::load_weights(&run.join("best"), &model.stage_groups(stage))?;
            crate::trainer::TrainingState::read(&run)?
        } else {
            for later in stage + 1..=3 {
                let stale = stage_dir(dir, later);
                if stale.exists() {
                    observer.epoch(&format!(
                        "{label} stage {later}: discarded, it was trained from stage {stage}'s weights before \
                         stage {stage} trained on"
                    ));
                    std::fs::remove_dir_all(&stale).map_err(|source| Error::Io {
                        path: stale.display().to_string(),
                        source,
                    })?;
                }
            }
            let trainer = crate::trainer::Trainer::new(format!("{label} stage {stage}"), config);
            trainer.run(&run, &mut EmbedStage::new(model, data, stage), observer)?
        };
        out.push((stage, state));
    }
    Ok(out)
}

/// Checks the stages asked for, reading `dir` only: each of 1, 2, 3, in increasing order,
/// and every earlier stage the configuration trains (epochs > 0) already trained in `dir`
/// — a later stage would otherwise start from untrained weights.
fn check_stages(dir: &std::path::Path, config: &EmbedTrainingSettings, stages: &[u8]) -> Result<()> {
    if let Some(&s) = stages.iter().find(|s| !(1..=3).contains(*s)) {
        return Err(crate::trainer::invalid("stages", s, "must be 1, 2 or 3"));
    }
    if !stages.windows(2).all(|w| w[0] < w[1]) {
        return Err(crate::trainer::invalid(
            "stages",
            stages,
            "must be in increasing order, each at most once (e.g. 1,2,3 or 2,3)",
        ));
    }
    for earlier in 1..stages.iter().copied().min().unwrap_or(1) {
        if config.trainer(earlier).epochs > 0 && !crate::trainer::has_run(&stage_dir(dir, earlier)) {
            return Err(Error::MissingStage {
                stage: earlier,
                dir: dir.display().to_string(),
            });
        }
    }
    Ok(())
}

/// Trains (or continues) the embedding on `data` into the model directory `dir`:
/// `config.json`, `normalization.json` (the ACAP feature normalisation fitted on the
/// training frames) and one trainer run per stage ([`train_stages`]). A directory trained
/// under another configuration is an error (only the epoch counts may change, and the
/// early-stopping patience grow: [`EmbedTrainingSettings::continues_as`]), except that a
/// model trained under another stage-3 learning rate keeps stages 1 and 2 and has its
/// stage 3 discarded ([`EmbedTrainingSettings::stages_continuing_as`]).
pub fn train_model(
    dir: &std::path::Path,
    data: &EmbedData,
    config: &EmbedTrainingSettings,
    stages: &[u8],
    observer: &mut dyn crate::trainer::Observer,
) -> Result<(EmbedModel, Vec<(u8, crate::trainer::TrainingState)>)> {
    config.validate()?;
    // Before anything is written, so a refused request leaves no model behind.
    check_stages(dir, config, stages)?;
    let io = |path: &std::path::Path, source: std::io::Error| Error::Io {
        path: path.display().to_string(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    let config_path = dir.join("config.json");
    if config_path.exists() {
        let stored: EmbedTrainingSettings = crate::checkpoint::read_json(&config_path)?;
        // The error names the fields that forbid continuing, not the epochs that may differ.
        let shown = EmbedTrainingSettings {
            epochs: config.epochs,
            kernels: config.kernels,
            ..stored.clone()
        };
        let kept = stored.stages_continuing_as(config);
        crate::checkpoint::check_continues(&config_path, kept > 0, &shown, config)?;
        for stage in kept + 1..=3 {
            let run = stage_dir(dir, stage);
            if run.exists() {
                observer.epoch(&format!(
                    "embed/{} stage {stage}: discarded, it was trained under another stage-{stage} configuration",
                    data.dataset.name
                ));
                std::fs::remove_dir_all(&run).map_err(|e| io(&run, e))?;
            }
        }
    }
    crate::checkpoint::write_json(&config_path, config)?;
    crate::checkpoint::write_json(&dir.join("normalization.json"), &data.normalization)?;
    let model = EmbedModel::new(config.clone(), data)?;
    let states = train_stages(
        dir,
        &model,
        data,
        stages,
        &format!("embed/{}", data.dataset.name),
        observer,
    )?;
    Ok((model, states))
}
