//! Training Alt-ConvLSTM and its baselines (§5.1): the settings, teacher-forced training
//! through the one [`crate::trainer::Trainer`] (fused kernels or autograd), the input
//! scaling fitted on the training split, and scoring a trained model on a sequence.

use candle_core::{DType, Device, Tensor};
use serde::{Deserialize, Serialize};

use super::fused::FusedWorkspace;
use super::model::{AltConvNet, Drive, HIDDEN, INPUT_CHANNELS, Scaling, Variant};
use super::runtime::AltConvRuntime;
use crate::Kernels;
use crate::error::{Error, Result};
use crate::graph::NormalizedAdjacency;
use crate::params::ParamStore;

impl Scaling {
    /// Fitted on the first `steps` steps of the training sequences: each input channel's
    /// mean and standard deviation over steps and vertices, and the RMS of what the
    /// variant's output state must represent — `Y_t − Y_{t−1} − (X_t − X_{t−1})` for a
    /// velocity, `Y_t − X_t` for the `-Y` baselines' offset. Floors of 1e-9 keep a
    /// constant channel finite.
    pub fn fit(train: &[SequenceTensors], variant: Variant, steps: usize) -> Result<Self> {
        if train.is_empty() {
            return Err(Error::InvalidParameter {
                name: "Alt-ConvLSTM scaling",
                value: "0 sequences".into(),
                reason: "needs at least one training sequence",
            });
        }
        let mut inputs: Vec<Tensor> = Vec::new();
        let mut targets: Vec<Tensor> = Vec::new();
        for s in train {
            let frames = s.truth.dim(1)?;
            let n = steps.min(frames - 1);
            let x = s.drive.skinned.narrow(1, 0, n + 1)?;
            let y = s.truth.narrow(1, 0, n + 1)?;
            let xt = x.narrow(1, 1, n)?;
            let dx = (&xt - x.narrow(1, 0, n)?)?;
            let offset = (&s.drive.initial - x.narrow(1, 0, 1)?.squeeze(1)?)?
                .unsqueeze(1)?
                .broadcast_as(xt.shape())?;
            inputs.push(Tensor::cat(&[&xt, &dx, &offset.contiguous()?], 3)?.reshape(((), INPUT_CHANNELS))?);
            let yt = y.narrow(1, 1, n)?;
            let target = if variant.outputs_position() {
                (&yt - &xt)?
            } else {
                ((&yt - y.narrow(1, 0, n)?)? - &dx)?
            };
            targets.push(target.flatten_all()?);
        }
        let inputs = Tensor::cat(&inputs, 0)?.to_dtype(DType::F64)?;
        let mean: Vec<f64> = inputs.mean(0)?.to_vec1()?;
        let std: Vec<f64> = inputs
            .broadcast_sub(&inputs.mean_keepdim(0)?)?
            .sqr()?
            .mean(0)?
            .sqrt()?
            .to_vec1()?;
        let rms = Tensor::cat(&targets, 0)?
            .to_dtype(DType::F64)?
            .sqr()?
            .mean_all()?
            .sqrt()?
            .to_scalar::<f64>()?;
        let scaling = Self {
            input_mean: std::array::from_fn(|d| mean[d]),
            input_std: std::array::from_fn(|d| std[d].max(1e-9)),
            output: rms.max(1e-9),
        };
        if !(scaling.output.is_finite()
            && scaling
                .input_mean
                .iter()
                .chain(&scaling.input_std)
                .all(|v| v.is_finite()))
        {
            return Err(Error::NonFinite {
                what: "Alt-ConvLSTM scaling",
                index: 0,
            });
        }
        Ok(scaling)
    }
}

/// Eq. 12: the mean Euclidean distance between predicted and true surfaces over steps and
/// vertices. `predictions[k]` is step `k + 1` of `truth` (`[B, T + 1, V, 3]`).
pub fn mean_vertex_error(predictions: &[Tensor], truth: &Tensor) -> Result<Tensor> {
    mean_vertex_error_stacked(&Tensor::stack(predictions, 1)?, truth)
}

/// [`mean_vertex_error`] of the predictions stacked as `[B, T, V, 3]` (what the fused
/// op returns).
pub fn mean_vertex_error_stacked(predicted: &Tensor, truth: &Tensor) -> Result<Tensor> {
    let steps = predicted.dim(1)?;
    let target = truth.narrow(1, 1, steps)?;
    // A tiny floor under the square root keeps the gradient finite at a perfect vertex.
    let d = ((predicted - target)?.sqr()?.sum(3)? + 1e-14)?.sqrt()?;
    Ok(d.mean_all()?)
}

/// Training recipe options beyond the paper's pure teacher forcing, all off by default
/// (they change results). The roll-out drift of the velocity-integrating models comes from
/// steps never trained on: a model trained only from true previous surfaces never sees its
/// own errors fed back.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Recipe {
    /// Scheduled sampling (Bengio et al. 2015): at each step `t > 1` the cell starts from
    /// the model's own previous prediction instead of the truth with probability `p(e)`,
    /// rising linearly over epochs `sampling_epochs[0]..sampling_epochs[1]` from 0 to
    /// `sampling_max` (0: pure teacher forcing, the paper's). The draws come from
    /// SplitMix64(seed, epoch, batch), so a resumed run draws the same.
    pub sampling_max: f64,
    pub sampling_epochs: [usize; 2],
    /// Curriculum: the trained window grows linearly from `curriculum_start` steps at epoch
    /// 0 to the configuration's `steps` at epoch `curriculum_epochs` (0: the full window from
    /// the start). Validation always scores the full window.
    pub curriculum_start: usize,
    pub curriculum_epochs: usize,
    /// Score validation as a roll-out (every step from the model's own previous
    /// prediction, as the evaluation scores it) instead of teacher-forced (the paper's
    /// Eq. 12 on the validation sequences). The kept epoch is the one that rolls out best:
    /// a teacher-forced score can fall while the roll-out drifts further.
    pub validation_rollout: bool,
}

impl Default for Recipe {
    fn default() -> Self {
        Self {
            sampling_max: 0.0,
            sampling_epochs: [0, 0],
            curriculum_start: 0,
            curriculum_epochs: 0,
            validation_rollout: false,
        }
    }
}

impl Recipe {
    /// The probability of feeding back the model's own prediction at epoch `epoch`.
    pub fn sampling_probability(&self, epoch: usize) -> f64 {
        let [a, b] = self.sampling_epochs;
        if self.sampling_max <= 0.0 || epoch < a {
            return 0.0;
        }
        if epoch >= b {
            return self.sampling_max;
        }
        self.sampling_max * (epoch - a) as f64 / (b - a) as f64
    }

    /// The trained window at epoch `epoch` when the full window is `steps`.
    pub fn window(&self, epoch: usize, steps: usize) -> usize {
        if self.curriculum_epochs == 0 || self.curriculum_start == 0 || epoch >= self.curriculum_epochs {
            return steps;
        }
        let start = self.curriculum_start.min(steps);
        start + (steps - start) * epoch / self.curriculum_epochs
    }

    /// Checks every field (`recipe.` prefixes the names in errors).
    pub fn validate(&self, steps: usize) -> Result<()> {
        use crate::trainer::invalid;
        if !(0.0..=1.0).contains(&self.sampling_max) {
            return Err(invalid("recipe.sampling_max", self.sampling_max, "must be in [0, 1]"));
        }
        if self.sampling_epochs[0] > self.sampling_epochs[1] {
            return Err(invalid(
                "recipe.sampling_epochs",
                self.sampling_epochs,
                "must be [start, end] with start <= end",
            ));
        }
        if self.curriculum_start > steps {
            return Err(invalid(
                "recipe.curriculum_start",
                self.curriculum_start,
                "must be at most steps",
            ));
        }
        Ok(())
    }
}

/// Training settings of one model (Alt-ConvLSTM §5.1). A stored configuration may omit
/// fields; they keep the defaults of [`AltConvTrainingSettings::new`] for Alt-ConvLSTM.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AltConvTrainingSettings {
    pub variant: Variant,
    pub hidden: Vec<usize>,
    /// Teacher-forced steps per training sequence (the paper: 20, after the initial frame).
    pub steps: usize,
    pub epochs: usize,
    /// Sequences per optimiser step.
    pub batch: usize,
    pub adam: crate::adam::AdamSettings,
    /// The learning-rate schedule; by default a factor 0.995 per epoch (the paper's
    /// "weight decay of 0.995").
    pub schedule: crate::trainer::Schedule,
    pub seed: u64,
    /// Scheduled sampling and a window curriculum (off by default).
    pub recipe: Recipe,
    /// The fused kernels (default) or candle's autograd, the reference. Not part of what a
    /// resumed run must match.
    pub kernels: Kernels,
}

impl Default for AltConvTrainingSettings {
    fn default() -> Self {
        Self::new(Variant::Alt)
    }
}

impl AltConvTrainingSettings {
    pub fn new(variant: Variant) -> Self {
        Self {
            variant,
            hidden: HIDDEN.to_vec(),
            steps: 20,
            epochs: 60,
            batch: 2,
            adam: crate::adam::AdamSettings {
                learning_rate: 1e-3,
                ..Default::default()
            },
            schedule: crate::trainer::Schedule {
                decay: crate::trainer::Decay::Exponential { per_epoch: 0.995 },
                ..Default::default()
            },
            seed: 0,
            recipe: Recipe::default(),
            kernels: Kernels::default(),
        }
    }

    /// Checks every field before any work: a typed error naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        use crate::trainer::{MAX_BATCH, MAX_EPOCHS, check_adam, check_count};
        check_count("hidden (number of layers)", self.hidden.len(), 64)?;
        for (i, &w) in self.hidden.iter().enumerate() {
            check_count(&format!("hidden[{i}]"), w, MAX_WIDTH)?;
        }
        check_count("steps", self.steps, 100_000)?;
        check_count("epochs", self.epochs, MAX_EPOCHS)?;
        check_count("batch", self.batch, MAX_BATCH)?;
        check_adam("adam", &self.adam)?;
        self.recipe.validate(self.steps)?;
        self.schedule.validate("schedule")
    }

    /// The trainer's part of the configuration.
    pub fn trainer(&self) -> crate::trainer::TrainerSettings {
        crate::trainer::TrainerSettings {
            epochs: self.epochs,
            batch: self.batch,
            seed: self.seed,
            schedule: self.schedule,
        }
    }
}

/// The widest layer a configuration may ask for: a graph ConvLSTM cell of width `w` holds
/// `8 w²` weights, 512 MB of f32 at this width, before Adam's moments.
pub const MAX_WIDTH: usize = 4096;

/// One sequence as tensors: its drive and its true surfaces `[1, F, V, 3]` (f32, metres).
#[derive(Debug, Clone)]
pub struct SequenceTensors {
    pub drive: Drive,
    pub truth: Tensor,
}

impl SequenceTensors {
    /// The first `frames` frames of `seq` (all of them if it has fewer).
    pub fn new(seq: &weft_data::LimbSequence, frames: usize, device: &Device) -> Result<Self> {
        let f = frames.min(seq.skinned.len());
        let v = seq.skinned[0].len() / 3;
        let stack = |frames: &[Vec<f64>], what: &'static str| -> Result<Tensor> {
            let flat: Vec<f64> = frames[..f].iter().flatten().copied().collect();
            let data = crate::convert::f64_to_f32(what, &flat)?;
            Ok(Tensor::from_vec(data, (1, f, v, 3), device)?)
        };
        let skinned = stack(&seq.skinned, "skinned surfaces")?;
        let truth = stack(&seq.simulated, "simulated surfaces")?;
        let initial = truth.narrow(1, 0, 1)?.squeeze(1)?;
        Ok(Self {
            drive: Drive { skinned, initial },
            truth,
        })
    }

    /// Several sequences of equal length as one batch.
    pub fn batch(items: &[&SequenceTensors]) -> Result<Self> {
        let cat = |f: &dyn Fn(&SequenceTensors) -> &Tensor| -> Result<Tensor> {
            Ok(Tensor::cat(&items.iter().map(|s| f(s)).collect::<Vec<_>>(), 0)?)
        };
        Ok(Self {
            drive: Drive {
                skinned: cat(&|s| &s.drive.skinned)?,
                initial: cat(&|s| &s.drive.initial)?,
            },
            truth: cat(&|s| &s.truth)?,
        })
    }
}

/// Teacher-forced training (§5.1, loss Eq. 12) of a network through
/// [`crate::trainer::Trainer`]: examples are the training sequences (each holding at
/// least `steps + 1` frames), the validation score is Eq. 12 on the validation sequences
/// (metres), teacher-forced or, with [`Recipe::validation_rollout`], rolled out.
#[derive(Debug)]
pub struct AltConvTraining<'a> {
    pub net: &'a AltConvNet,
    pub params: &'a ParamStore,
    pub adj: &'a NormalizedAdjacency,
    pub train: &'a [SequenceTensors],
    pub validation: &'a [SequenceTensors],
    pub steps: usize,
    pub adam: crate::adam::AdamSettings,
    /// Scheduled sampling and the window curriculum, drawn from `seed`.
    pub recipe: Recipe,
    pub seed: u64,
    /// The fused kernels (with their reused buffers) or candle's autograd.
    pub path: TrainingPath,
}

/// How [`AltConvTraining`] computes its loss and gradients.
#[derive(Debug, Clone)]
pub enum TrainingPath {
    Fused(FusedWorkspace),
    Autograd,
}

impl TrainingPath {
    pub fn new(kernels: Kernels) -> Self {
        match kernels {
            Kernels::Fused => Self::Fused(FusedWorkspace::new()),
            Kernels::Autograd => Self::Autograd,
        }
    }
}

impl crate::trainer::Trainable for AltConvTraining<'_> {
    fn groups(&self) -> Vec<crate::trainer::Group<'_>> {
        vec![crate::trainer::Group {
            name: "net",
            params: self.params,
            adam: self.adam,
        }]
    }

    fn num_examples(&self) -> usize {
        self.train.len()
    }

    fn batch_loss(&mut self, batch: &[usize], at: crate::trainer::BatchAt) -> Result<crate::trainer::BatchLoss> {
        let items: Vec<&SequenceTensors> = batch.iter().map(|&k| &self.train[k]).collect();
        let b = SequenceTensors::batch(&items)?;
        let steps = self.recipe.window(at.epoch, self.steps);
        let p = self.recipe.sampling_probability(at.epoch);
        // One draw per step from SplitMix64(seed, epoch, batch): the same on a resumed run.
        let forced: Vec<bool> = {
            let mut rng = weft_sim::rng::SplitMix64::new(
                self.seed ^ (at.epoch as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ ((at.batch as u64) << 40),
            );
            (0..=steps).map(|_| rng.unit() >= p).collect()
        };
        let loss = match &self.path {
            TrainingPath::Fused(workspace) => {
                let predicted = self
                    .net
                    .run_fused(self.adj, &b.drive, Some(&b.truth), steps, &forced, workspace)?;
                mean_vertex_error_stacked(&predicted, &b.truth)?
            }
            TrainingPath::Autograd => {
                let predictions = self
                    .net
                    .run_forced(self.adj, &b.drive, Some(&b.truth), steps, &|t| forced[t])?;
                mean_vertex_error(&predictions, &b.truth)?
            }
        };
        Ok(crate::trainer::BatchLoss::Loss { loss, terms: vec![] })
    }

    fn validation_score(&mut self) -> Result<f64> {
        if self.validation.is_empty() {
            return Err(Error::InvalidParameter {
                name: "validation split",
                value: "0 sequences".into(),
                reason: "model selection needs at least one validation sequence",
            });
        }
        match &self.path {
            TrainingPath::Fused(workspace) => {
                let mut total = 0.0;
                let forced = vec![!self.recipe.validation_rollout; self.steps + 1];
                for s in self.validation {
                    let predicted =
                        self.net
                            .run_fused(self.adj, &s.drive, Some(&s.truth), self.steps, &forced, workspace)?;
                    total += mean_vertex_error_stacked(&predicted, &s.truth)?
                        .to_dtype(DType::F64)?
                        .to_scalar::<f64>()?;
                }
                Ok(total / self.validation.len() as f64)
            }
            TrainingPath::Autograd => mean_error(
                self.net,
                self.adj,
                self.validation,
                self.steps,
                !self.recipe.validation_rollout,
            ),
        }
    }
}

/// Eq. 12 of a model on `sequences` over `steps` steps, teacher-forced (`single_step`) or
/// rolled out, averaged over sequences (metres).
pub fn mean_error(
    net: &AltConvNet,
    adj: &NormalizedAdjacency,
    sequences: &[SequenceTensors],
    steps: usize,
    single_step: bool,
) -> Result<f64> {
    let mut total = 0.0;
    for s in sequences {
        let predictions = net.run(adj, &s.drive, single_step.then_some(&s.truth), steps)?;
        total += mean_vertex_error(&predictions, &s.truth)?
            .to_dtype(DType::F64)?
            .to_scalar::<f64>()?;
    }
    Ok(total / sequences.len().max(1) as f64)
}

/// A trained model directory written by `cargo xtask train altconv`: `config.json`,
/// `scaling.json` and the trainer's run, loaded at its best validation weights.
pub fn load_model(dir: &std::path::Path, device: &Device) -> Result<(AltConvTrainingSettings, ParamStore, AltConvNet)> {
    crate::checkpoint::check_model_kind(dir, "altconv")?;
    let path = dir.join("config.json");
    let text = std::fs::read_to_string(&path).map_err(|source| Error::Io {
        path: path.display().to_string(),
        source,
    })?;
    let config: AltConvTrainingSettings = serde_json::from_str(&text).map_err(|e| Error::Checkpoint {
        path: path.display().to_string(),
        reason: e.to_string(),
    })?;
    let scaling_path = dir.join("scaling.json");
    let scaling: Scaling = match std::fs::read_to_string(&scaling_path) {
        Ok(text) => serde_json::from_str(&text).map_err(|e| Error::Checkpoint {
            path: scaling_path.display().to_string(),
            reason: e.to_string(),
        })?,
        Err(source) => {
            return Err(Error::Io {
                path: scaling_path.display().to_string(),
                source,
            });
        }
    };
    let mut params = ParamStore::new(device, config.seed);
    let net = AltConvNet::new(&mut params, config.variant, &config.hidden)?.with_scaling(scaling);
    crate::checkpoint::load_params(&dir.join("best").join("net"), &params)?;
    Ok((config, params, net))
}

/// How a model (or skinning) does on one sequence over `steps` steps.
#[derive(Debug, Clone)]
pub struct SequenceErrors {
    /// Per step, per vertex `‖Ŷ_t − Y_t‖` (m): single-step (teacher-forced) and roll-out.
    pub single: Vec<Vec<f64>>,
    pub rollout: Vec<Vec<f64>>,
    /// The roll-out's surfaces, steps 1..=`steps` (flat `3V` each, m).
    pub rollout_surfaces: Vec<Vec<f64>>,
    /// Wall time of the roll-out (s).
    pub rollout_seconds: f64,
}

/// Scores `net` (skinning when `None`) on `seq` over `steps` steps: a roll-out and a
/// teacher-forced run, both through [`AltConvRuntime`] (which reproduces the candle model,
/// tested) on `adj`, the mesh of `seq`.
pub fn score_sequence(
    net: Option<&AltConvNet>,
    adj: &NormalizedAdjacency,
    seq: &weft_data::LimbSequence,
    steps: usize,
) -> Result<SequenceErrors> {
    if steps == 0 || steps >= seq.skinned.len() {
        return Err(Error::InvalidParameter {
            name: "scored steps",
            value: steps.to_string(),
            reason: "needs at least one step and one more frame than steps",
        });
    }
    let (x, y) = (&seq.skinned, &seq.simulated);
    let errors = |predicted: &[Vec<f64>]| -> Vec<Vec<f64>> {
        predicted
            .iter()
            .zip(&y[1..])
            .map(|(p, t)| {
                p.chunks_exact(3)
                    .zip(t.chunks_exact(3))
                    .map(|(a, b)| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt())
                    .collect()
            })
            .collect()
    };
    let t = std::time::Instant::now();
    let (rolled, forced) = match net {
        None => {
            // Ŷ_t = X_t + (Y_0 − X_0): the surface carried by the skin alone.
            let p: Vec<Vec<f64>> = (1..=steps)
                .map(|k| {
                    x[k].iter()
                        .zip(&x[0])
                        .zip(&y[0])
                        .map(|((xt, x0), y0)| xt + y0 - x0)
                        .collect()
                })
                .collect();
            (p.clone(), p)
        }
        Some(net) => {
            let mut runtime = AltConvRuntime::new(net, adj.clone())?;
            runtime.start(&x[0], &y[0])?;
            let rolled = (1..=steps).map(|k| runtime.step(&x[k])).collect::<Result<Vec<_>>>()?;
            runtime.start(&x[0], &y[0])?;
            let forced = (1..=steps)
                .map(|k| runtime.step_from(&x[k], Some(&y[k - 1])))
                .collect::<Result<Vec<_>>>()?;
            (rolled, forced)
        }
    };
    // The roll-out's share of the time: half of the two runs (the skinning row's are one).
    let rollout_seconds = t.elapsed().as_secs_f64() / if net.is_some() { 2.0 } else { 1.0 };
    Ok(SequenceErrors {
        single: errors(&forced),
        rollout: errors(&rolled),
        rollout_surfaces: rolled,
        rollout_seconds,
    })
}

/// A model trained by [`train_model`], at its best validation weights.
#[derive(Debug)]
pub struct TrainedAltConv {
    pub state: crate::trainer::TrainingState,
    pub params: ParamStore,
    pub net: AltConvNet,
    pub adj: NormalizedAdjacency,
}

/// Trains (or continues, up to `config.epochs`) a model on the `limb` dataset into the
/// model directory `dir`: `config.json`, `scaling.json` (fitted on the training
/// sequences) and the trainer's run (`training.json`, `train.log`, `best/net`,
/// `last/net`). The validation split selects the kept weights; the test split is not
/// read. A directory trained under another configuration (bar the epoch count) is an
/// error.
pub fn train_model(
    dir: &std::path::Path,
    dataset: &weft_data::LimbDataset,
    config: &AltConvTrainingSettings,
    observer: &mut dyn crate::trainer::Observer,
) -> Result<TrainedAltConv> {
    config.validate()?;
    let device = Device::Cpu;
    let tensors = |split: &str| -> Result<Vec<SequenceTensors>> {
        dataset
            .split(split)
            .map(|s| {
                if s.skinned.len() <= config.steps {
                    return Err(Error::Dataset {
                        path: dataset.dir.display().to_string(),
                        reason: format!(
                            "configuration field `steps` = {} needs sequences of steps + 1 frames, and {} sequence {} \
                             has {}: set steps to at most {}",
                            config.steps,
                            split,
                            s.index,
                            s.skinned.len(),
                            s.skinned.len().saturating_sub(1)
                        ),
                    });
                }
                SequenceTensors::new(s, config.steps + 1, &device)
            })
            .collect()
    };
    let train = tensors("train")?;
    let validation = tensors("validation")?;
    if train.is_empty() || validation.is_empty() {
        return Err(Error::Dataset {
            path: dataset.dir.display().to_string(),
            reason: format!(
                "needs training and validation sequences (it has {} and {})",
                train.len(),
                validation.len()
            ),
        });
    }
    let adj = NormalizedAdjacency::new(&dataset.rest)?;
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        path: dir.display().to_string(),
        source,
    })?;
    let config_path = dir.join("config.json");
    let scaling_path = dir.join("scaling.json");
    let scaling: Scaling = if crate::trainer::has_run(dir) {
        let stored: AltConvTrainingSettings = crate::checkpoint::read_json(&config_path)?;
        let stored = AltConvTrainingSettings {
            epochs: config.epochs,
            kernels: config.kernels,
            ..stored
        };
        // The early-stopping patience may grow too (the trainer's rule).
        let mut same = stored.clone();
        same.schedule.early_stopping_patience = config.schedule.early_stopping_patience;
        let continues = stored.trainer().continues_as(&config.trainer()) && same == *config;
        crate::checkpoint::check_continues(&config_path, continues, &stored, config)?;
        crate::checkpoint::read_json(&scaling_path)?
    } else {
        let s = Scaling::fit(&train, config.variant, config.steps)?;
        crate::checkpoint::write_json(&scaling_path, &s)?;
        s
    };
    crate::checkpoint::write_json(&config_path, config)?;
    let mut params = ParamStore::new(&device, config.seed);
    let net = AltConvNet::new(&mut params, config.variant, &config.hidden)?.with_scaling(scaling);
    let mut training = AltConvTraining {
        net: &net,
        params: &params,
        adj: &adj,
        train: &train,
        validation: &validation,
        steps: config.steps,
        adam: config.adam,
        recipe: config.recipe,
        seed: config.seed,
        path: TrainingPath::new(config.kernels),
    };
    let trainer = crate::trainer::Trainer::new(format!("altconv/{}", config.variant.name()), config.trainer());
    let state = trainer.run(dir, &mut training, observer)?;
    Ok(TrainedAltConv {
        state,
        params,
        net,
        adj,
    })
}
