//! The one training loop of weft: every model — an embedding stage, the NNWarp MLP,
//! Alt-ConvLSTM and its baselines, the drape network — trains through [`Trainer`].
//!
//! A model plugs in through [`Trainable`]: its parameter groups (each with its own Adam),
//! the loss on a batch of training examples, and a validation score. The trainer owns
//! everything else: the epoch order (Fisher–Yates on SplitMix64, seeded per epoch), the
//! learning-rate schedule ([`Schedule`]: constant, exponential decay, warm-up,
//! reduce-on-plateau), optional gradient clipping by the global norm, model selection and
//! early stopping on the **validation score only** (the trainer never sees a test split),
//! a checkpoint after every epoch, bit-identical resume, and one log line per epoch.
//!
//! A run directory holds:
//! - `training.json` ([`TrainingState`]): the trainer's configuration, epochs done, the
//!   best epoch and its score, the schedule's state and one [`EpochRecord`] per epoch;
//! - `last/<group>/` and `best/<group>/`: checkpoints ([`crate::checkpoint`]) of each
//!   parameter group after the latest epoch and at the best validation score (epoch 0,
//!   the starting weights, included: a fine-tune that only gets worse keeps them);
//! - `train.log`: the epoch lines, as the observer also receives them.
//!
//! Everything is written under a temporary name and renamed into place, `training.json`
//! last, so a run stopped at any moment resumes from its last complete epoch and continues
//! bit for bit: the state after epoch `k` depends only on the configuration, the data and
//! the seed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use candle_core::Tensor;
use candle_core::backprop::GradStore;
use serde::{Deserialize, Serialize};

use crate::adam::{Adam, AdamSettings, gradient_sq_norm};
use crate::error::{Error, Result};
use crate::params::ParamStore;

/// How the learning rate moves from epoch to epoch after warm-up.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Decay {
    /// The base learning rate throughout.
    Constant,
    /// `base · per_epoch^epoch`.
    Exponential { per_epoch: f64 },
    /// Multiplied by `factor` whenever the validation score has not improved for
    /// `patience` epochs.
    ReduceOnPlateau { factor: f64, patience: usize },
}

/// The learning-rate schedule and the stopping rules of a run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Schedule {
    pub decay: Decay,
    /// Epochs over which the learning rate rises linearly to its scheduled value (epoch
    /// `e < warmup_epochs` runs at `(e + 1) / (warmup_epochs + 1)` of it).
    pub warmup_epochs: usize,
    /// Batches over which the learning rate rises linearly from the run's first batch
    /// (batch `s < warmup_steps`, counted from the start of the run as epoch · batches
    /// per epoch + batch, at `(s + 1) / (warmup_steps + 1)` of its epoch's rate).
    ///
    /// Why: Adam's first steps move every weight by about the learning rate against its
    /// gradient's sign, whatever the gradient's size (its moment estimates are one sample
    /// old). A layer summing many inputs of one sign — the embedding's fully connected
    /// encoder layer reads 38 025 mostly positive activations on the standard sheet —
    /// therefore moves its output by `lr · Σ|h|` in one step, which can push the next
    /// layers into saturation before the moments settle (Liu et al. 2020, "On the
    /// Variance of the Adaptive Learning Rate and Beyond", §3; docs/EMBEDDING.md).
    pub warmup_steps: usize,
    /// Scale every group's gradient down so their joint Euclidean norm is at most this.
    pub clip_grad_norm: Option<f64>,
    /// Stop when the validation score has not improved for this many epochs.
    pub early_stopping_patience: Option<usize>,
}

impl Default for Schedule {
    fn default() -> Self {
        Self {
            decay: Decay::Constant,
            warmup_epochs: 0,
            warmup_steps: 0,
            clip_grad_norm: None,
            early_stopping_patience: None,
        }
    }
}

/// Largest accepted epoch count, batch size and warm-up or patience length: beyond them a
/// value is a typo, not a plan.
pub const MAX_EPOCHS: usize = 1_000_000;
pub const MAX_BATCH: usize = 1 << 24;
pub const MAX_WARMUP_STEPS: usize = 1 << 30;

/// A configuration field out of its range, as a typed error naming the field.
pub fn invalid(field: &str, value: impl std::fmt::Debug, reason: &'static str) -> Error {
    Error::InvalidSettings {
        field: field.to_string(),
        value: format!("{value:?}"),
        reason,
    }
}

/// Checks a learning rate: finite, positive, at most 1.
pub fn check_learning_rate(field: &str, lr: f64) -> Result<()> {
    if !(lr > 0.0 && lr <= 1.0) {
        return Err(invalid(field, lr, "must be in (0, 1]"));
    }
    Ok(())
}

/// Checks a count that must lie in `1..=max`.
pub fn check_count(field: &str, value: usize, max: usize) -> Result<()> {
    if value == 0 || value > max {
        return Err(Error::InvalidSettings {
            field: field.to_string(),
            value: value.to_string(),
            reason: if value == 0 {
                "must be at least 1"
            } else {
                "is beyond any sensible size"
            },
        });
    }
    Ok(())
}

/// Checks Adam's settings of a parameter group (`field` prefixes the names).
pub fn check_adam(field: &str, adam: &AdamSettings) -> Result<()> {
    check_learning_rate(&format!("{field}.learning_rate"), adam.learning_rate)?;
    for (name, b) in [("beta1", adam.beta1), ("beta2", adam.beta2)] {
        if !(0.0..1.0).contains(&b) {
            return Err(invalid(&format!("{field}.{name}"), b, "must be in [0, 1)"));
        }
    }
    if !(adam.epsilon > 0.0 && adam.epsilon.is_finite()) {
        return Err(invalid(
            &format!("{field}.epsilon"),
            adam.epsilon,
            "must be positive and finite",
        ));
    }
    Ok(())
}

impl Schedule {
    /// Checks every field (`field` prefixes the names in errors).
    pub fn validate(&self, field: &str) -> Result<()> {
        match self.decay {
            Decay::Constant => {}
            Decay::Exponential { per_epoch } => {
                if !(per_epoch > 0.0 && per_epoch <= 1.0) {
                    return Err(invalid(
                        &format!("{field}.decay.per_epoch"),
                        per_epoch,
                        "must be in (0, 1]",
                    ));
                }
            }
            Decay::ReduceOnPlateau { factor, patience } => {
                if !(factor > 0.0 && factor < 1.0) {
                    return Err(invalid(&format!("{field}.decay.factor"), factor, "must be in (0, 1)"));
                }
                check_count(&format!("{field}.decay.patience"), patience, MAX_EPOCHS)?;
            }
        }
        if self.warmup_epochs > MAX_EPOCHS {
            return Err(invalid(
                &format!("{field}.warmup_epochs"),
                self.warmup_epochs,
                "is beyond any sensible size",
            ));
        }
        if self.warmup_steps > MAX_WARMUP_STEPS {
            return Err(invalid(
                &format!("{field}.warmup_steps"),
                self.warmup_steps,
                "is beyond any sensible size",
            ));
        }
        if let Some(c) = self.clip_grad_norm {
            if !(c > 0.0 && c.is_finite()) {
                return Err(invalid(
                    &format!("{field}.clip_grad_norm"),
                    c,
                    "must be positive and finite",
                ));
            }
        }
        if let Some(p) = self.early_stopping_patience {
            check_count(&format!("{field}.early_stopping_patience"), p, MAX_EPOCHS)?;
        }
        Ok(())
    }
}

/// The trainer's own settings; everything model-specific stays in the model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrainerSettings {
    /// Epochs in all (a resumed run continues up to this many).
    pub epochs: usize,
    /// Training examples per step.
    pub batch: usize,
    /// Seeds the epoch order.
    pub seed: u64,
    pub schedule: Schedule,
}

impl TrainerSettings {
    pub fn validate(&self) -> Result<()> {
        check_count("epochs", self.epochs, MAX_EPOCHS)?;
        check_count("batch", self.batch, MAX_BATCH)?;
        self.schedule.validate("schedule")
    }

    /// Whether a run trained under `self` can be continued under `other`: only the epoch
    /// count may differ, and the early-stopping patience may grow (`None` is unlimited).
    /// A longer patience stops no earlier, so every epoch already trained is one a fresh
    /// run under `other` trains too; no schedule depends on the epoch count.
    pub fn continues_as(&self, other: &Self) -> bool {
        let longer = match (
            self.schedule.early_stopping_patience,
            other.schedule.early_stopping_patience,
        ) {
            (_, None) => true,
            (None, Some(_)) => false,
            (Some(a), Some(b)) => b >= a,
        };
        let mut same = *self;
        same.epochs = other.epochs;
        same.schedule.early_stopping_patience = other.schedule.early_stopping_patience;
        longer && same == *other
    }

    /// Whether a run that has gone `epochs_since_best` epochs without improving stops here.
    fn stops(&self, epochs_since_best: usize) -> bool {
        self.schedule
            .early_stopping_patience
            .is_some_and(|p| epochs_since_best >= p)
    }
}

/// One parameter group: its own Adam (and learning rate), its own checkpoint directory.
#[derive(Debug)]
pub struct Group<'a> {
    /// The directory name under `last/` and `best/`.
    pub name: &'static str,
    pub params: &'a ParamStore,
    /// Adam at the base learning rate; the schedule scales it.
    pub adam: AdamSettings,
}

/// Where a batch falls in training (for losses whose weights ramp within an epoch).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BatchAt {
    /// 0-based epoch.
    pub epoch: usize,
    /// 0-based batch of the epoch, of `batches`.
    pub batch: usize,
    pub batches: usize,
}

/// What a model made of a batch.
#[derive(Debug)]
pub enum BatchLoss {
    /// A scalar loss to minimise, and the named terms to log (unweighted values).
    Loss {
        loss: Tensor,
        terms: Vec<(&'static str, f64)>,
    },
    /// The batch cannot be trained on (a projection layer failed on one of its
    /// examples); no step is taken, the batch is counted and the first reason kept.
    Skipped { reason: String },
}

/// A model as the trainer sees it.
pub trait Trainable {
    /// The parameter groups this run trains.
    fn groups(&self) -> Vec<Group<'_>>;
    /// Training examples; batches are index sets into `0..num_examples()`.
    fn num_examples(&self) -> usize;
    /// Forward pass and loss on training examples `batch`.
    fn batch_loss(&mut self, batch: &[usize], at: BatchAt) -> Result<BatchLoss>;
    /// The score on the validation split after an epoch (lower is better). It must be
    /// finite; a model without validation data is an error, never a silent 0.
    fn validation_score(&mut self) -> Result<f64>;
    /// Sees each step's gradients before the optimiser does (e.g. to record a learned
    /// parameter's gradient statistics).
    fn after_backward(&mut self, _grads: &GradStore) -> Result<()> {
        Ok(())
    }
    /// Model-specific entries of the epoch's record (e.g. a learned μ), also logged.
    fn epoch_extra(&mut self) -> Result<BTreeMap<String, f64>> {
        Ok(BTreeMap::new())
    }
    /// Seed of epoch `epoch`'s order. The default mixes the epoch in with the golden
    /// ratio; models trained before the trainer existed keep their own streams so their
    /// runs are reproduced bit for bit.
    fn shuffle_seed(&self, seed: u64, epoch: usize) -> u64 {
        seed ^ (epoch as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
    }
}

/// One epoch of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    /// 1-based: the record after `epoch` epochs.
    pub epoch: usize,
    /// Mean training loss over the examples of the batches that trained.
    pub loss: f64,
    /// Mean of each logged term over the same examples.
    pub terms: BTreeMap<String, f64>,
    /// The validation score after the epoch.
    pub validation: f64,
    /// The (group-0) learning rate of the epoch.
    pub learning_rate: f64,
    /// Seconds spent in training steps, and in the validation pass.
    pub train_seconds: f64,
    pub validation_seconds: f64,
    pub skipped_batches: usize,
    #[serde(default)]
    pub first_skip: Option<String>,
    /// The model's own entries ([`Trainable::epoch_extra`]).
    #[serde(default)]
    pub extra: BTreeMap<String, f64>,
}

/// Where a run stands, `training.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainingState {
    pub config: TrainerSettings,
    pub epochs_done: usize,
    /// The validation score of the starting weights (epoch 0).
    pub initial_validation: f64,
    /// The epoch whose weights are kept (0: the starting weights), and its score.
    pub best_epoch: usize,
    pub best_validation: f64,
    /// The reduce-on-plateau factor so far, and the epochs since the last improvement.
    pub lr_factor: f64,
    pub epochs_since_best: usize,
    /// The run ended before `config.epochs` because the validation score stalled.
    pub stopped_early: bool,
    pub history: Vec<EpochRecord>,
}

impl TrainingState {
    /// Reads a run directory's `training.json`.
    pub fn read(dir: &Path) -> Result<Self> {
        let path = dir.join("training.json");
        let text = std::fs::read_to_string(&path).map_err(|e| io_error(&path, e))?;
        serde_json::from_str(&text).map_err(|e| Error::Checkpoint {
            path: path.display().to_string(),
            reason: e.to_string(),
        })
    }

    /// Total seconds spent in training steps.
    pub fn train_seconds(&self) -> f64 {
        self.history.iter().map(|h| h.train_seconds).sum()
    }

    /// The median over the epochs of an epoch's wall seconds in training steps (0 before
    /// the first epoch); with an even count, the mean of the middle two. The cost of an
    /// epoch as a user would quote it: an epoch slowed by another process, or stretched
    /// by a pause of the whole run (`kill -STOP`), moves [`Self::train_seconds`] but not
    /// this, as long as fewer than half the epochs are affected.
    pub fn median_epoch_seconds(&self) -> f64 {
        let mut t: Vec<f64> = self.history.iter().map(|h| h.train_seconds).collect();
        if t.is_empty() {
            return 0.0;
        }
        t.sort_by(f64::total_cmp);
        let n = t.len();
        if n % 2 == 1 {
            t[n / 2]
        } else {
            0.5 * (t[n / 2 - 1] + t[n / 2])
        }
    }

    /// Whether the run is complete under `config` (its epochs all trained, or stopped by
    /// `config`'s early stopping), so continuing it would train nothing more.
    pub fn finished_under(&self, config: &TrainerSettings) -> bool {
        self.epochs_done >= config.epochs || config.stops(self.epochs_since_best)
    }

    /// Whether continuing this run under `config` gives exactly the run a fresh trainer
    /// under `config` would make: `config` continues the run's configuration
    /// ([`TrainerSettings::continues_as`]) and allows at least the epochs already trained
    /// (a shorter budget could have kept another epoch's weights).
    pub fn continues_exactly_as(&self, config: &TrainerSettings) -> bool {
        self.config.continues_as(config) && self.epochs_done <= config.epochs
    }

    /// Training batches skipped over the run, and the first reason.
    pub fn skipped(&self) -> (usize, Option<&str>) {
        (
            self.history.iter().map(|h| h.skipped_batches).sum(),
            self.history.iter().find_map(|h| h.first_skip.as_deref()),
        )
    }
}

/// Receives a run's progress: a progress bar, a log, nothing.
pub trait Observer {
    /// Training is about to run `batches` batches in all.
    fn start(&mut self, _batches: u64) {}
    /// A batch trained (or was skipped) with this loss (NaN when skipped).
    fn batch(&mut self, _epoch: usize, _loss: f64) {}
    /// An epoch's log line (the same line `train.log` receives).
    fn epoch(&mut self, _line: &str) {}
}

/// An observer that ignores everything.
#[derive(Debug, Default)]
pub struct Silent;
impl Observer for Silent {}

/// An observer that prints epoch lines to standard error (for a run without a terminal).
#[derive(Debug, Default)]
pub struct EpochLines;
impl Observer for EpochLines {
    fn epoch(&mut self, line: &str) {
        eprintln!("{line}");
    }
}

/// The one training loop.
#[derive(Debug, Clone)]
pub struct Trainer {
    pub config: TrainerSettings,
    /// Written at the start of every log line (e.g. `altconv/alt`).
    pub label: String,
}

fn io_error(path: &Path, source: std::io::Error) -> Error {
    Error::Io {
        path: path.display().to_string(),
        source,
    }
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".partial");
    let tmp = PathBuf::from(tmp);
    std::fs::write(&tmp, bytes).map_err(|e| io_error(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| io_error(path, e))
}

/// Replaces directory `current` by `fresh` through renames: an interruption leaves the
/// old or the new one whole (or both, as `current` and `*.old`).
fn swap_in(fresh: &Path, current: &Path) -> Result<()> {
    let old = current.with_extension("old");
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(|e| io_error(&old, e))?;
    }
    if current.exists() {
        std::fs::rename(current, &old).map_err(|e| io_error(current, e))?;
    }
    std::fs::rename(fresh, current).map_err(|e| io_error(current, e))?;
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(|e| io_error(&old, e))?;
    }
    Ok(())
}

/// Saves every group and its Adam into `dir` (replaced whole).
fn save_groups(dir: &Path, groups: &[Group<'_>], adams: &[Adam]) -> Result<()> {
    let mut fresh = dir.as_os_str().to_owned();
    fresh.push(".partial");
    let fresh = PathBuf::from(fresh);
    if fresh.exists() {
        std::fs::remove_dir_all(&fresh).map_err(|e| io_error(&fresh, e))?;
    }
    for (g, adam) in groups.iter().zip(adams) {
        crate::checkpoint::save(&fresh.join(g.name), g.params, adam, &serde_json::Value::Null)?;
    }
    swap_in(&fresh, dir)
}

/// Restores the parameters of every group from `dir` (a `best/` or `last/` directory of a
/// run), without optimiser state — how a trained model is loaded for inference.
pub fn load_weights(dir: &Path, groups: &[Group<'_>]) -> Result<()> {
    for g in groups {
        crate::checkpoint::load_params(&dir.join(g.name), g.params)?;
    }
    Ok(())
}

/// Whether `dir` holds a run the trainer can resume.
pub fn has_run(dir: &Path) -> bool {
    dir.join("training.json").is_file()
}

/// Whether the run in `dir` still holds its weights: a complete checkpoint of every
/// parameter group under both `last/` and `best/` (a copy of the small files alone, a
/// run's `training.json` without them, cannot be continued).
pub fn has_checkpoints(dir: &Path) -> bool {
    ["last", "best"].iter().all(|kind| {
        std::fs::read_dir(dir.join(kind)).is_ok_and(|entries| {
            let groups: Vec<PathBuf> = entries.flatten().map(|e| e.path()).filter(|p| p.is_dir()).collect();
            !groups.is_empty() && groups.iter().all(|g| crate::checkpoint::exists(g))
        })
    })
}

/// Epoch order: Fisher–Yates over `0..n` drawn from SplitMix64(`seed`).
pub fn shuffled(n: usize, seed: u64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).collect();
    let mut rng = weft_sim::rng::SplitMix64::new(seed);
    for i in (1..n).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        order.swap(i, j);
    }
    order
}

impl Trainer {
    pub fn new(label: impl Into<String>, config: TrainerSettings) -> Self {
        Self {
            config,
            label: label.into(),
        }
    }

    /// The learning-rate multiplier of `epoch` (0-based), given the plateau factor.
    pub fn lr_factor(&self, epoch: usize, plateau: f64) -> f64 {
        let s = &self.config.schedule;
        let decay = match s.decay {
            Decay::Exponential { per_epoch } => per_epoch.powi(epoch as i32),
            Decay::Constant | Decay::ReduceOnPlateau { .. } => 1.0,
        };
        let warm = if epoch < s.warmup_epochs {
            (epoch + 1) as f64 / (s.warmup_epochs + 1) as f64
        } else {
            1.0
        };
        decay * plateau * warm
    }

    /// The warm-up multiplier of batch `step` (0-based, counted over the run):
    /// [`Schedule::warmup_steps`].
    pub fn step_factor(&self, step: usize) -> f64 {
        let w = self.config.schedule.warmup_steps;
        if step < w {
            (step + 1) as f64 / (w + 1) as f64
        } else {
            1.0
        }
    }

    /// Trains `model` in `dir`, continuing the run there if one exists (up to
    /// `config.epochs`), and leaves the model at its best validation weights.
    ///
    /// A run already in `dir` must have been trained under the same configuration but
    /// for its epoch count; the caller decides whether an existing run may be continued
    /// at all (the command line asks for `--resume`).
    pub fn run(&self, dir: &Path, model: &mut dyn Trainable, observer: &mut dyn Observer) -> Result<TrainingState> {
        self.config.validate()?;
        let n = model.num_examples();
        if n == 0 {
            return Err(invalid("training data", 0, "holds no training example"));
        }
        std::fs::create_dir_all(dir).map_err(|e| io_error(dir, e))?;
        let state_path = dir.join("training.json");
        let mut adams: Vec<Adam> = model
            .groups()
            .iter()
            .map(|g| Adam::new(g.params, g.adam))
            .collect::<Result<_>>()?;
        let mut state = if has_run(dir) {
            let state = TrainingState::read(dir)?;
            if !state.config.continues_as(&self.config) {
                return Err(Error::Checkpoint {
                    path: state_path.display().to_string(),
                    reason: format!(
                        "the run was trained under {:?}, not {:?} (only the epoch count may change, and the \
                         early-stopping patience grow)",
                        state.config, self.config
                    ),
                });
            }
            if state.epochs_done > 0 {
                let groups = model.groups();
                for (g, adam) in groups.iter().zip(adams.iter_mut()) {
                    crate::checkpoint::load(&dir.join("last").join(g.name), g.params, adam)?;
                }
            }
            let mut state = state;
            state.config = self.config;
            // Under a longer patience a run that stopped early goes on.
            state.stopped_early = self.config.stops(state.epochs_since_best);
            state
        } else {
            let t = Instant::now();
            let initial = self.checked_score(model)?;
            let groups = model.groups();
            save_groups(&dir.join("best"), &groups, &adams)?;
            save_groups(&dir.join("last"), &groups, &adams)?;
            let state = TrainingState {
                config: self.config,
                epochs_done: 0,
                initial_validation: initial,
                best_epoch: 0,
                best_validation: initial,
                lr_factor: 1.0,
                epochs_since_best: 0,
                stopped_early: false,
                history: Vec::new(),
            };
            write_atomic(&state_path, &serde_json::to_vec_pretty(&state).expect("plain data"))?;
            self.log(
                dir,
                observer,
                &format!(
                    "{}: epoch 0 (starting weights): validation {initial:.6e} ({:.1} s)",
                    self.label,
                    t.elapsed().as_secs_f64()
                ),
            )?;
            state
        };
        let batch = self.config.batch;
        let batches = n.div_ceil(batch);
        let remaining = if state.stopped_early {
            0
        } else {
            self.config.epochs.saturating_sub(state.epochs_done)
        };
        observer.start((remaining * batches) as u64);
        for epoch in state.epochs_done..self.config.epochs {
            if state.stopped_early {
                break;
            }
            let factor = self.lr_factor(epoch, state.lr_factor);
            let order = shuffled(n, model.shuffle_seed(self.config.seed, epoch));
            let start = Instant::now();
            let (mut loss_sum, mut trained) = (0.0, 0usize);
            let mut terms: BTreeMap<String, f64> = BTreeMap::new();
            let (mut skipped, mut first_skip) = (0usize, None);
            for (k, chunk) in order.chunks(batch).enumerate() {
                // The run's step count decides the warm-up, so a resumed run continues it.
                let warm = self.step_factor(epoch * batches + k);
                for (g, adam) in model.groups().iter().zip(adams.iter_mut()) {
                    adam.settings.learning_rate = g.adam.learning_rate * factor * warm;
                }
                let at = BatchAt {
                    epoch,
                    batch: k,
                    batches,
                };
                match model.batch_loss(chunk, at)? {
                    BatchLoss::Skipped { reason } => {
                        skipped += 1;
                        first_skip.get_or_insert(reason);
                        observer.batch(epoch, f64::NAN);
                    }
                    BatchLoss::Loss { loss, terms: t } => {
                        let value = loss.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>()?;
                        if !value.is_finite() {
                            return Err(Error::NonFinite {
                                what: "training loss",
                                index: k,
                            });
                        }
                        let grads = loss.backward()?;
                        model.after_backward(&grads)?;
                        let groups = model.groups();
                        let scale = match self.config.schedule.clip_grad_norm {
                            Some(max) => {
                                let mut sq = 0.0;
                                for g in &groups {
                                    sq += gradient_sq_norm(g.params, &grads)?;
                                }
                                let norm = sq.sqrt();
                                if norm > max { max / norm } else { 1.0 }
                            }
                            None => 1.0,
                        };
                        for (g, adam) in groups.iter().zip(adams.iter_mut()) {
                            adam.step_scaled(g.params, &grads, scale)?;
                        }
                        let w = chunk.len() as f64;
                        loss_sum += value * w;
                        for (name, v) in t {
                            *terms.entry(name.to_string()).or_insert(0.0) += v * w;
                        }
                        trained += chunk.len();
                        observer.batch(epoch, value);
                    }
                }
            }
            if trained == 0 {
                return Err(Error::InvalidParameter {
                    name: "training epoch",
                    value: first_skip.unwrap_or_default(),
                    reason: "every batch was skipped",
                });
            }
            let train_seconds = start.elapsed().as_secs_f64();
            let t = Instant::now();
            let validation = self.checked_score(model)?;
            let validation_seconds = t.elapsed().as_secs_f64();
            terms.values_mut().for_each(|v| *v /= trained as f64);
            let record = EpochRecord {
                epoch: epoch + 1,
                loss: loss_sum / trained as f64,
                terms,
                validation,
                learning_rate: adams.first().map_or(0.0, Adam::learning_rate),
                train_seconds,
                validation_seconds,
                skipped_batches: skipped,
                first_skip,
                extra: model.epoch_extra()?,
            };
            let improved = validation < state.best_validation;
            let groups = model.groups();
            if improved {
                state.best_validation = validation;
                state.best_epoch = epoch + 1;
                state.epochs_since_best = 0;
                save_groups(&dir.join("best"), &groups, &adams)?;
            } else {
                state.epochs_since_best += 1;
                if let Decay::ReduceOnPlateau { factor, patience } = self.config.schedule.decay {
                    if state.epochs_since_best % patience == 0 {
                        state.lr_factor *= factor;
                    }
                }
                state.stopped_early = self.config.stops(state.epochs_since_best);
            }
            save_groups(&dir.join("last"), &groups, &adams)?;
            drop(groups);
            let line = self.epoch_line(&record, improved, state.stopped_early);
            state.history.push(record);
            state.epochs_done = epoch + 1;
            write_atomic(&state_path, &serde_json::to_vec_pretty(&state).expect("plain data"))?;
            self.log(dir, observer, &line)?;
        }
        load_weights(&dir.join("best"), &model.groups())?;
        Ok(state)
    }

    fn checked_score(&self, model: &mut dyn Trainable) -> Result<f64> {
        let v = model.validation_score()?;
        if !v.is_finite() {
            return Err(Error::NonFinite {
                what: "validation score",
                index: 0,
            });
        }
        Ok(v)
    }

    fn epoch_line(&self, r: &EpochRecord, improved: bool, stopped: bool) -> String {
        let mut line = format!(
            "{}: epoch {}/{}: loss {:.6e}",
            self.label, r.epoch, self.config.epochs, r.loss
        );
        for (k, v) in &r.terms {
            line.push_str(&format!(" {k} {v:.4e}"));
        }
        line.push_str(&format!(
            ", validation {:.6e}{}, lr {:.3e}, {:.1} s + {:.1} s validation",
            r.validation,
            if improved { " (best)" } else { "" },
            r.learning_rate,
            r.train_seconds,
            r.validation_seconds
        ));
        for (k, v) in &r.extra {
            line.push_str(&format!(", {k} {v:.4e}"));
        }
        if r.skipped_batches > 0 {
            line.push_str(&format!(", {} batches skipped", r.skipped_batches));
        }
        if stopped {
            line.push_str(", early stop");
        }
        line
    }

    fn log(&self, dir: &Path, observer: &mut dyn Observer, line: &str) -> Result<()> {
        use std::io::Write;
        let path = dir.join("train.log");
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(|e| io_error(&path, e))?;
        writeln!(f, "{line}").map_err(|e| io_error(&path, e))?;
        observer.epoch(line);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Init;
    use candle_core::Device;

    /// Linear regression `y = w·x` on fixed data, validated on held-out points.
    struct Line {
        params: ParamStore,
        w: Tensor,
        x: Vec<f32>,
        y: Vec<f32>,
        vx: Vec<f32>,
        vy: Vec<f32>,
        lr: f64,
    }

    impl Line {
        fn new(lr: f64) -> Self {
            let mut params = ParamStore::new(&Device::Cpu, 3);
            let w = params.create("w", &[1], Init::Constant(0.0)).unwrap();
            let x: Vec<f32> = (0..20).map(|i| i as f32 / 10.0).collect();
            let y = x.iter().map(|x| 2.0 * x + 0.1 * (x * 7.0).sin()).collect();
            let vx = vec![0.55, 1.25];
            let vy = vec![1.1, 2.5];
            Self {
                params,
                w,
                x,
                y,
                vx,
                vy,
                lr,
            }
        }

        fn weight(&self) -> f32 {
            self.params.vars()["w"].as_tensor().to_vec1::<f32>().unwrap()[0]
        }

        fn mse(&self, x: &[f32], y: &[f32]) -> Result<Tensor> {
            let xs = Tensor::from_slice(x, x.len(), &Device::Cpu)?;
            let ys = Tensor::from_slice(y, y.len(), &Device::Cpu)?;
            Ok((xs.broadcast_mul(&self.w)? - ys)?.sqr()?.mean_all()?)
        }
    }

    impl Trainable for Line {
        fn groups(&self) -> Vec<Group<'_>> {
            vec![Group {
                name: "line",
                params: &self.params,
                adam: AdamSettings {
                    learning_rate: self.lr,
                    ..AdamSettings::default()
                },
            }]
        }
        fn num_examples(&self) -> usize {
            self.x.len()
        }
        fn batch_loss(&mut self, batch: &[usize], _at: BatchAt) -> Result<BatchLoss> {
            let x: Vec<f32> = batch.iter().map(|&i| self.x[i]).collect();
            let y: Vec<f32> = batch.iter().map(|&i| self.y[i]).collect();
            Ok(BatchLoss::Loss {
                loss: self.mse(&x, &y)?,
                terms: vec![],
            })
        }
        fn validation_score(&mut self) -> Result<f64> {
            Ok(f64::from(self.mse(&self.vx, &self.vy)?.to_scalar::<f32>()?))
        }
    }

    fn config(epochs: usize) -> TrainerSettings {
        TrainerSettings {
            epochs,
            batch: 3,
            seed: 7,
            schedule: Schedule::default(),
        }
    }

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("weft-trainer-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn the_median_epoch_ignores_a_paused_epoch() {
        let d = tmp("median");
        let mut model = Line::new(0.05);
        let mut state = Trainer::new("t", config(4)).run(&d, &mut model, &mut Silent).unwrap();
        for (h, t) in state.history.iter_mut().zip([2.0, 700.0, 3.0, 4.0]) {
            h.train_seconds = t;
        }
        // Even count: the mean of the middle two; the 700 s epoch does not count.
        assert_eq!(state.median_epoch_seconds(), 3.5);
        assert_eq!(state.train_seconds(), 709.0);
        state.history.pop();
        assert_eq!(state.median_epoch_seconds(), 3.0);
        state.history.clear();
        assert_eq!(state.median_epoch_seconds(), 0.0);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn resumed_runs_continue_bit_for_bit() {
        let (a, b) = (tmp("straight"), tmp("resumed"));
        let mut straight = Line::new(0.05);
        let s = Trainer::new("t", config(6))
            .run(&a, &mut straight, &mut Silent)
            .unwrap();
        let mut first = Line::new(0.05);
        Trainer::new("t", config(2)).run(&b, &mut first, &mut Silent).unwrap();
        // A fresh process: new weights, everything else from the directory.
        let mut resumed = Line::new(0.05);
        let r = Trainer::new("t", config(6)).run(&b, &mut resumed, &mut Silent).unwrap();
        assert_eq!(straight.weight().to_bits(), resumed.weight().to_bits());
        let strip =
            |s: &TrainingState| -> Vec<(f64, f64)> { s.history.iter().map(|h| (h.loss, h.validation)).collect() };
        assert_eq!(strip(&s), strip(&r));
        assert_eq!(std::fs::read_to_string(b.join("train.log")).unwrap().lines().count(), 7);
    }

    /// The per-batch warm-up: each epoch's last batch runs at the documented fraction, a
    /// run resumed inside the ramp continues it bit for bit, and the ramp changes the run.
    #[test]
    fn warmup_ramps_by_batch_and_a_run_resumed_mid_ramp_continues_it() {
        let warm = |epochs| TrainerSettings {
            schedule: Schedule {
                warmup_steps: 20,
                ..Schedule::default()
            },
            ..config(epochs)
        };
        let t = Trainer::new("t", warm(1));
        assert_eq!(
            [t.step_factor(0), t.step_factor(19), t.step_factor(20)],
            [1.0 / 21.0, 20.0 / 21.0, 1.0]
        );
        let (a, b, c) = (tmp("warm-straight"), tmp("warm-resumed"), tmp("cold"));
        let mut straight = Line::new(0.05);
        let s = Trainer::new("t", warm(5)).run(&a, &mut straight, &mut Silent).unwrap();
        // 20 examples in batches of 3: 7 batches an epoch, so epoch e's last batch is
        // batch 7e + 6 of the run.
        let last_lr: Vec<f64> = s.history.iter().map(|h| h.learning_rate).collect();
        let expected: Vec<f64> = (0..5).map(|e| 0.05 * t.step_factor(7 * e + 6)).collect();
        for (got, want) in last_lr.iter().zip(&expected) {
            assert!((got - want).abs() < 1e-12, "{last_lr:?} vs {expected:?}");
        }
        assert!(expected[1] < 0.05 && expected[2] == 0.05);
        // Stopped after epoch 2 (batch 13 of the 20-batch ramp), resumed in a new process.
        Trainer::new("t", warm(2))
            .run(&b, &mut Line::new(0.05), &mut Silent)
            .unwrap();
        let mut resumed = Line::new(0.05);
        Trainer::new("t", warm(5)).run(&b, &mut resumed, &mut Silent).unwrap();
        assert_eq!(straight.weight().to_bits(), resumed.weight().to_bits());
        let mut cold = Line::new(0.05);
        Trainer::new("t", config(5)).run(&c, &mut cold, &mut Silent).unwrap();
        assert_ne!(straight.weight(), cold.weight());
        for d in [a, b, c] {
            let _ = std::fs::remove_dir_all(d);
        }
    }

    #[test]
    fn keeps_the_weights_of_the_best_validation_epoch() {
        let d = tmp("best");
        // A learning rate so large that training overshoots and validation worsens.
        let mut m = Line::new(2.0);
        let s = Trainer::new("t", config(8)).run(&d, &mut m, &mut Silent).unwrap();
        let best = s
            .history
            .iter()
            .map(|h| (h.epoch, h.validation))
            .chain([(0, s.initial_validation)])
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        assert_eq!(s.best_epoch, best.0);
        assert_ne!(
            s.best_epoch, 8,
            "the run must end worse than its best for this test to bite"
        );
        let kept = m.validation_score().unwrap();
        assert_eq!(kept, best.1);
    }

    #[test]
    fn schedules_give_the_documented_factors() {
        let mut c = config(10);
        c.schedule = Schedule {
            decay: Decay::Exponential { per_epoch: 0.5 },
            warmup_epochs: 3,
            ..Schedule::default()
        };
        let t = Trainer::new("t", c);
        assert_eq!(t.lr_factor(0, 1.0), 0.25);
        assert_eq!(t.lr_factor(2, 1.0), 0.25 * 0.75);
        assert_eq!(t.lr_factor(4, 0.1), 0.0625 * 0.1);
    }

    #[test]
    fn early_stopping_and_plateau_follow_the_validation_score() {
        let d = tmp("plateau");
        let mut c = config(30);
        c.schedule = Schedule {
            decay: Decay::ReduceOnPlateau {
                factor: 0.5,
                patience: 1,
            },
            early_stopping_patience: Some(3),
            ..Schedule::default()
        };
        let mut m = Line::new(2.0);
        let s = Trainer::new("t", c).run(&d, &mut m, &mut Silent).unwrap();
        assert!(s.stopped_early);
        assert_eq!(s.epochs_done, s.best_epoch + 3);
        // The learning rate halves after every epoch without improvement.
        let (mut best, mut factor) = (s.initial_validation, 1.0);
        for h in &s.history {
            assert_eq!(h.learning_rate, 2.0 * factor, "epoch {}", h.epoch);
            if h.validation < best {
                best = h.validation;
            } else {
                factor *= 0.5;
            }
        }
        assert!(factor < 1.0);
    }

    #[test]
    fn a_run_stopped_early_continues_under_a_longer_patience_as_a_fresh_run_would() {
        let with_patience = |epochs: usize, p: Option<usize>| {
            let mut c = config(epochs);
            c.schedule = Schedule {
                decay: Decay::ReduceOnPlateau {
                    factor: 0.5,
                    patience: 1,
                },
                early_stopping_patience: p,
                ..Schedule::default()
            };
            c
        };
        let (a, b) = (tmp("patient"), tmp("extended"));
        let mut fresh = Line::new(2.0);
        let f = Trainer::new("t", with_patience(30, Some(4)))
            .run(&a, &mut fresh, &mut Silent)
            .unwrap();
        let short = Trainer::new("t", with_patience(30, Some(1)))
            .run(&b, &mut Line::new(2.0), &mut Silent)
            .unwrap();
        assert!(short.stopped_early);
        assert!(
            short.epochs_done < f.epochs_done,
            "the longer patience must train more epochs for this test to bite"
        );
        assert!(!short.finished_under(&with_patience(30, Some(4))));
        assert!(short.finished_under(&with_patience(30, Some(1))));
        assert!(short.continues_exactly_as(&with_patience(30, Some(4))));
        assert!(!short.continues_exactly_as(&with_patience(short.epochs_done - 1, Some(4))));
        // A shorter patience could have stopped before the epochs already trained.
        assert!(!f.config.continues_as(&with_patience(30, Some(1))));
        assert!(f.config.continues_as(&with_patience(30, None)));
        assert!(!with_patience(30, None).continues_as(&f.config));
        let mut extended = Line::new(2.0);
        let e = Trainer::new("t", with_patience(30, Some(4)))
            .run(&b, &mut extended, &mut Silent)
            .unwrap();
        assert_eq!(fresh.weight().to_bits(), extended.weight().to_bits());
        let strip = |s: &TrainingState| -> Vec<(f64, f64, f64)> {
            s.history
                .iter()
                .map(|h| (h.loss, h.validation, h.learning_rate))
                .collect()
        };
        assert_eq!(strip(&f), strip(&e));
        assert_eq!((f.best_epoch, f.stopped_early), (e.best_epoch, e.stopped_early));
        let shorter = Trainer::new("t", with_patience(30, Some(2)))
            .run(&a, &mut Line::new(2.0), &mut Silent)
            .unwrap_err();
        assert!(shorter.to_string().contains("patience grow"), "{shorter}");
    }

    #[test]
    fn clipping_scales_the_steps_of_a_run() {
        let run = |clip: Option<f64>, name: &str| {
            let mut c = config(3);
            c.schedule.clip_grad_norm = clip;
            let mut m = Line::new(0.1);
            Trainer::new("t", c).run(&tmp(name), &mut m, &mut Silent).unwrap();
            m.weight()
        };
        let (free, loose, tight) = (run(None, "noclip"), run(Some(1e9), "loose"), run(Some(1e-3), "tight"));
        // A bound never reached changes nothing; a tight one changes the relative sizes of
        // Adam's steps (every gradient is scaled to the same norm).
        assert_eq!(free.to_bits(), loose.to_bits());
        assert_ne!(free, tight);
        assert!(tight.is_finite());
    }

    #[test]
    fn gradient_norm_is_the_analytic_one() {
        let m = Line::new(0.1);
        let loss = m.mse(&m.x, &m.y).unwrap();
        let grads = loss.backward().unwrap();
        // d/dw mean((w x − y)²) at w = 0 is −2 mean(x y).
        let g = -2.0 * m.x.iter().zip(&m.y).map(|(x, y)| f64::from(x * y)).sum::<f64>() / m.x.len() as f64;
        let sq = gradient_sq_norm(&m.params, &grads).unwrap();
        assert!((sq - g * g).abs() < 1e-5 * g * g, "{sq} vs {}", g * g);
    }

    #[test]
    fn bad_configurations_name_their_field() {
        let mut c = config(0);
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("epochs"), "{e}");
        c.epochs = 1;
        c.schedule.decay = Decay::Exponential { per_epoch: f64::NAN };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("schedule.decay.per_epoch"), "{e}");
        c.schedule.decay = Decay::Constant;
        c.schedule.warmup_steps = MAX_WARMUP_STEPS + 1;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("schedule.warmup_steps"), "{e}");
        c.schedule.warmup_steps = MAX_WARMUP_STEPS;
        c.validate().unwrap();
        assert!(
            check_learning_rate("adam.learning_rate", 1e9)
                .unwrap_err()
                .to_string()
                .contains("adam.learning_rate")
        );
    }

    #[test]
    fn a_changed_configuration_is_not_resumed() {
        let d = tmp("changed");
        Trainer::new("t", config(1))
            .run(&d, &mut Line::new(0.05), &mut Silent)
            .unwrap();
        let mut c = config(2);
        c.seed = 8;
        let e = Trainer::new("t", c)
            .run(&d, &mut Line::new(0.05), &mut Silent)
            .unwrap_err();
        assert!(e.to_string().contains("only the epoch count"), "{e}");
    }
}
