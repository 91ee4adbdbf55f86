//! The nonlinear inertial correction (docs/GUARD.md, "A nonlinear correction"): the linear
//! one-step surrogate of [`crate::inertial_correction`] with a small MLP on its features
//! adding to its correction codes,
//!
//! ```text
//! p̂_m = 2p_{m−1} − p_{m−2} + U_c clip(b(f_m) + s · MLP(f_m)),                          (G9)
//! ```
//!
//! - `f_m`, `U_c` and the clip are the linear model's (Eq. G7: the standardised codes of
//!   `p_{m−1}` and `p_{m−1} − p_{m−2}` in the training frames' PCA, the controls and the
//!   grasp's acceleration; the PCA of the training residuals; each code clipped to its
//!   training range widened by a quarter) — one implementation, weft-surrogate's, called;
//! - the base `b` is the linear correction's codes `W [f; 1]` ([`Base::Linear`], the
//!   default) or zero ([`Base::Predictor`]): the MLP's last layer starts at zero, so the
//!   starting weights *are* the base model, and the trainer's model selection (epoch 0
//!   included) keeps a network never worse than it on the validation frames;
//! - `s`: one scale, the RMS of the codes the network must add on the training windows,
//!   so it works on numbers of order one; the loss is the squared code error in those
//!   units — by the basis' orthonormality, the squared position error of the part of the
//!   residual `U_c` spans;
//! - training runs through the one [`Trainer`], with the validation frames' one-step M_rms
//!   (mm, through the same prediction as the guard's proposals) as the score that selects
//!   the kept epoch and stops the run early; seeded (weights and epoch order).
//!
//! The network runs in f32; features, codes and frames are f64, converted at
//! [`crate::convert`]. A model directory holds `config.json` (`kind`
//! `inertial-correction-mlp`, the settings, the output scale and the validation figures),
//! `linear/` (the linear model's directory, its bases and weights) and `net/` (the
//! trainer's run: `training.json`, `train.log`, `best/`, `last/`).

use std::path::Path;
use std::sync::Arc;

use candle_core::{Device, Tensor};
use weft_data::ClothDataset;
use weft_surrogate::inertial_correction::{
    InertialCorrection, InertialCorrectionSettings, frame_mm, history, split_windows,
};

use crate::adam::AdamSettings;
use crate::error::{Error, Result};
use crate::layers::{Dense, leaky_relu};
use crate::params::{Init, ParamStore};
use crate::trainer::{
    BatchAt, BatchLoss, Group, Observer, Schedule, Trainable, Trainer, TrainerSettings, TrainingState, check_adam,
    check_count,
};

/// The model kind in `config.json`.
pub const KIND: &str = weft_surrogate::model_dir::INERTIAL_CORRECTION_MLP;

/// The trainer's run inside a model directory.
const RUN: &str = "net";

/// Widest hidden layer accepted: beyond it a width is a typo, not a plan.
const MAX_WIDTH: usize = 1 << 16;

/// What the network adds to (module docs, Eq. G9).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Base {
    /// The linear correction's codes: the network learns what the ridge fit leaves.
    Linear,
    /// Nothing: the network learns the whole correction of the inertial predictor.
    Predictor,
}

/// How the correction is fitted.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InertialCorrectionMlpSettings {
    /// The linear model whose features, basis and clip the network shares.
    pub linear: InertialCorrectionSettings,
    pub base: Base,
    /// Widths of the hidden layers (leaky ReLU after each).
    pub hidden: Vec<usize>,
    pub adam: AdamSettings,
    pub batch: usize,
    pub epochs: usize,
    /// Seeds the initial weights and the epoch order.
    pub seed: u64,
    pub schedule: Schedule,
}

impl Default for InertialCorrectionMlpSettings {
    fn default() -> Self {
        Self {
            linear: InertialCorrectionSettings::default(),
            base: Base::Linear,
            hidden: vec![128, 128],
            adam: AdamSettings::default(),
            batch: 16,
            epochs: 200,
            seed: 0,
            schedule: Schedule {
                early_stopping_patience: Some(30),
                ..Schedule::default()
            },
        }
    }
}

impl InertialCorrectionMlpSettings {
    /// Checks every field before any work (the linear model's fields are checked by its fit).
    pub fn validate(&self) -> Result<()> {
        if self.hidden.is_empty() {
            return Err(crate::trainer::invalid(
                "hidden",
                &self.hidden,
                "needs at least one layer",
            ));
        }
        for w in &self.hidden {
            check_count("hidden", *w, MAX_WIDTH)?;
        }
        check_adam("adam", &self.adam)?;
        self.trainer().validate()
    }

    fn trainer(&self) -> TrainerSettings {
        TrainerSettings {
            epochs: self.epochs,
            batch: self.batch,
            seed: self.seed,
            schedule: self.schedule,
        }
    }

    /// Whether a model trained under `self` can be continued under `other`: everything but
    /// the trainer's epochs and patience must agree ([`TrainerSettings::continues_as`]).
    pub fn continues_as(&self, other: &Self) -> bool {
        let mut same = other.clone();
        (same.epochs, same.schedule) = (self.epochs, self.schedule);
        same == *self && self.trainer().continues_as(&other.trainer())
    }
}

/// One-step M_rms (mm) on the validation windows of the three models a fit compares.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ValidationFigures {
    pub predictor_mm: f64,
    pub linear_mm: f64,
    /// The network at its kept epoch.
    pub mlp_mm: f64,
}

/// `config.json`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Meta {
    kind: String,
    settings: InertialCorrectionMlpSettings,
    /// `s` of Eq. G9 (m per network unit).
    scale: f64,
    /// Written once training is done.
    validation: Option<ValidationFigures>,
}

/// The network: dense layers with leaky ReLUs between, the last one started at zero.
#[derive(Debug, Clone)]
struct Mlp {
    layers: Vec<Dense>,
}

impl Mlp {
    fn new(params: &mut ParamStore, inputs: usize, hidden: &[usize], outputs: usize) -> Result<Self> {
        let mut layers = Vec::new();
        let mut width = inputs;
        for (i, &h) in hidden.iter().enumerate() {
            layers.push(Dense::new(params, &format!("layer{i}"), width, h)?);
            width = h;
        }
        // Zero, so the starting weights are the base model (module docs).
        let last = hidden.len();
        layers.push(Dense {
            weight: params.create(&format!("layer{last}.w"), &[width, outputs], Init::Zeros)?,
            bias: params.create(&format!("layer{last}.b"), &[outputs], Init::Zeros)?,
        });
        Ok(Self { layers })
    }

    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mut h = x.clone();
        for (i, layer) in self.layers.iter().enumerate() {
            h = layer.forward(&h)?;
            if i + 1 < self.layers.len() {
                h = leaky_relu(&h)?;
            }
        }
        Ok(h)
    }
}

/// A trained nonlinear inertial correction (module docs). Cheap to clone: the weights are
/// shared.
#[derive(Debug, Clone)]
pub struct InertialCorrectionMlp {
    meta: Meta,
    linear: InertialCorrection,
    params: Arc<ParamStore>,
    net: Mlp,
}

/// The inputs of a set of windows: standardised features and the base codes (f64).
struct Inputs {
    features: Vec<Vec<f64>>,
    base: Vec<Vec<f64>>,
}

impl InertialCorrectionMlp {
    fn build(meta: Meta, linear: InertialCorrection, seed: u64) -> Result<Self> {
        let mut params = ParamStore::new(&Device::Cpu, seed ^ 0x1C0E_C7ED);
        let net = Mlp::new(
            &mut params,
            linear.num_features(),
            &meta.settings.hidden,
            linear.num_codes(),
        )?;
        Ok(Self {
            meta,
            linear,
            params: Arc::new(params),
            net,
        })
    }

    /// The standardised features and base codes of `windows` of `data`.
    fn inputs(&self, data: &ClothDataset, windows: &[(usize, usize)]) -> Result<Inputs> {
        let mut inputs = Inputs {
            features: Vec::with_capacity(windows.len()),
            base: Vec::with_capacity(windows.len()),
        };
        for &(s, m) in windows {
            let seq = &data.sequences[s];
            let (p2, p1) = history(seq, m);
            let f = self.linear.features(p2, p1, seq.control(m))?;
            inputs.base.push(self.base_codes(&f));
            inputs.features.push(f);
        }
        Ok(inputs)
    }

    fn base_codes(&self, features: &[f64]) -> Vec<f64> {
        match self.meta.settings.base {
            Base::Linear => self.linear.linear_codes(features),
            Base::Predictor => vec![0.0; self.linear.num_codes()],
        }
    }

    /// The correction codes of each window, `clip(b + s · MLP(f))`, the network run once
    /// on all of them.
    fn codes(&self, inputs: &Inputs) -> Result<Vec<Vec<f64>>> {
        let (n, k) = (inputs.features.len(), self.linear.num_codes());
        if n == 0 {
            return Ok(Vec::new());
        }
        let f = crate::convert::f64_to_tensor(
            "correction features",
            &inputs.features.concat(),
            &[n, self.linear.num_features()],
            &Device::Cpu,
        )?;
        let out = crate::convert::tensor_to_f64("predicted correction codes", &self.net.forward(&f)?)?;
        Ok(out
            .chunks_exact(k)
            .zip(&inputs.base)
            .map(|(d, b)| {
                let mut c: Vec<f64> = b.iter().zip(d).map(|(b, d)| b + self.meta.scale * d).collect();
                self.linear.clip_codes(&mut c);
                c
            })
            .collect())
    }

    /// Each window's one-step M_rms (mm) from the true history.
    fn errors_at(&self, data: &ClothDataset, windows: &[(usize, usize)]) -> Result<Vec<f64>> {
        let codes = self.codes(&self.inputs(data, windows)?)?;
        windows
            .iter()
            .zip(&codes)
            .map(|(&(s, m), c)| {
                let seq = &data.sequences[s];
                let (p2, p1) = history(seq, m);
                let x = self.linear.with_codes(p2, p1, seq.control(m), c)?;
                Ok(frame_mm(&x, seq.frame(m)))
            })
            .collect()
    }

    /// Each frame's one-step error (M_rms, mm) on `split` of `data` (`train`, `validation`
    /// or `test`, the linear model's windows), from the true history.
    pub fn one_step_errors(&self, data: &ClothDataset, split: &str) -> Result<Vec<f64>> {
        self.linear.check_dataset(data)?;
        self.errors_at(data, &split_windows(data, split)?)
    }

    /// Frame `p_m` (flat positions, m) from `p_{m−2}`, `p_{m−1}` and the controls `q_m`
    /// (3 per grasped vertex, in the grasp's order).
    pub fn predict(&self, p2: &[f64], p1: &[f64], q: &[f64]) -> Result<Vec<f64>> {
        let f = self.linear.features(p2, p1, q)?;
        let inputs = Inputs {
            base: vec![self.base_codes(&f)],
            features: vec![f],
        };
        let codes = self.codes(&inputs)?;
        Ok(self.linear.with_codes(p2, p1, q, &codes[0])?)
    }

    /// The linear model the network builds on (its features, basis and clip).
    pub fn linear(&self) -> &InertialCorrection {
        &self.linear
    }

    pub fn settings(&self) -> &InertialCorrectionMlpSettings {
        &self.meta.settings
    }

    /// The validation figures of the fit (`None` for a run stopped before they were written).
    pub fn validation(&self) -> Option<ValidationFigures> {
        self.meta.validation
    }

    /// Trains the correction on `data` in the model directory `dir` (module docs),
    /// continuing a run there trained under the same settings but for its epochs and
    /// patience, and returns the model at its kept epoch with the trainer's record.
    pub fn train(
        dir: &Path,
        data: &ClothDataset,
        settings: &InertialCorrectionMlpSettings,
        observer: &mut dyn Observer,
    ) -> Result<(Self, TrainingState)> {
        settings.validate()?;
        let config = dir.join("config.json");
        if config.exists() {
            crate::checkpoint::check_model_kind(dir, KIND)?;
            let stored: Meta = crate::checkpoint::read_json(&config)?;
            let continues = stored.settings.continues_as(settings);
            crate::checkpoint::check_continues(&config, continues, &stored.settings, settings)?;
        }
        let linear = InertialCorrection::fit(data, &settings.linear)?;
        let meta = Meta {
            kind: KIND.into(),
            settings: settings.clone(),
            scale: 1.0,
            validation: None,
        };
        let mut model = Self::build(meta, linear, settings.seed)?;
        let (train, validation) = (split_windows(data, "train")?, split_windows(data, "validation")?);
        let inputs = model.inputs(data, &train)?;
        let targets = train
            .iter()
            .map(|&(s, m)| {
                let seq = &data.sequences[s];
                let (p2, p1) = history(seq, m);
                Ok(model.linear.residual_codes(p2, p1, seq.control(m), seq.frame(m))?)
            })
            .collect::<Result<Vec<_>>>()?;
        let deltas: Vec<f64> = targets
            .iter()
            .zip(&inputs.base)
            .flat_map(|(t, b)| t.iter().zip(b).map(|(t, b)| t - b).collect::<Vec<_>>())
            .collect();
        let ms = deltas.iter().map(|d| d * d).sum::<f64>() / deltas.len().max(1) as f64;
        // A residual the base already fits exactly leaves nothing to scale: keep 1 m.
        model.meta.scale = if ms > 0.0 { ms.sqrt() } else { 1.0 };
        std::fs::create_dir_all(dir).map_err(|source| Error::Io {
            path: dir.display().to_string(),
            source,
        })?;
        model.linear.save(&dir.join("linear"))?;
        crate::checkpoint::write_json(&config, &model.meta)?;
        let (n, k) = (train.len(), model.linear.num_codes());
        let scaled: Vec<f64> = deltas.iter().map(|d| d / model.meta.scale).collect();
        let mut training = Training {
            model: &model,
            data,
            validation: &validation,
            features: crate::convert::f64_to_tensor(
                "correction features",
                &inputs.features.concat(),
                &[n, model.linear.num_features()],
                &Device::Cpu,
            )?,
            targets: crate::convert::f64_to_tensor("correction targets", &scaled, &[n, k], &Device::Cpu)?,
        };
        let trainer = Trainer::new(format!("inertial-correction-mlp/{}", data.name), settings.trainer());
        let state = trainer.run(&dir.join(RUN), &mut training, observer)?;
        let mut predictor = model.linear.clone();
        predictor.disable_correction();
        model.meta.validation = Some(ValidationFigures {
            predictor_mm: rms(&predictor.one_step_errors(data, "validation")?),
            linear_mm: rms(&model.linear.one_step_errors(data, "validation")?),
            mlp_mm: rms(&model.errors_at(data, &validation)?),
        });
        crate::checkpoint::write_json(&config, &model.meta)?;
        Ok((model, state))
    }

    /// Reads a model directory written by [`InertialCorrectionMlp::train`], at its kept
    /// epoch; a directory of another kind is refused by name.
    pub fn load(dir: &Path) -> Result<Self> {
        crate::checkpoint::check_model_kind(dir, KIND)?;
        let meta: Meta = crate::checkpoint::read_json(&dir.join("config.json"))?;
        if meta.kind != KIND {
            return Err(Error::Checkpoint {
                path: dir.join("config.json").display().to_string(),
                reason: format!("kind `{}`, not `{KIND}`", meta.kind),
            });
        }
        let linear = InertialCorrection::load(&dir.join("linear"))?;
        let seed = meta.settings.seed;
        let model = Self::build(meta, linear, seed)?;
        let group = model.group();
        crate::trainer::load_weights(&dir.join(RUN).join("best"), &[group])?;
        Ok(model)
    }

    fn group(&self) -> Group<'_> {
        Group {
            name: "mlp",
            params: &self.params,
            adam: self.meta.settings.adam,
        }
    }
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// The trainer's view: training windows as tensors, validation through the model's own
/// one-step prediction.
struct Training<'a> {
    model: &'a InertialCorrectionMlp,
    data: &'a ClothDataset,
    validation: &'a [(usize, usize)],
    /// `[N, features]`, f32.
    features: Tensor,
    /// `(c − b) / s`, `[N, codes]`, f32.
    targets: Tensor,
}

impl Trainable for Training<'_> {
    fn groups(&self) -> Vec<Group<'_>> {
        vec![self.model.group()]
    }

    fn num_examples(&self) -> usize {
        self.features.dim(0).unwrap_or(0)
    }

    fn batch_loss(&mut self, batch: &[usize], _at: BatchAt) -> Result<BatchLoss> {
        let idx: Vec<u32> = batch.iter().map(|&i| i as u32).collect();
        let idx = Tensor::from_vec(idx, batch.len(), &Device::Cpu)?;
        let predicted = self.model.net.forward(&self.features.index_select(&idx, 0)?)?;
        let loss = (predicted - self.targets.index_select(&idx, 0)?)?
            .sqr()?
            .sum(1)?
            .mean_all()?;
        Ok(BatchLoss::Loss { loss, terms: vec![] })
    }

    /// One-step M_rms (mm) on the validation frames, through [`InertialCorrectionMlp::predict`]'s path.
    fn validation_score(&mut self) -> Result<f64> {
        if self.validation.is_empty() {
            return Err(Error::InvalidParameter {
                name: "validation split",
                value: "0 windows".into(),
                reason: "model selection needs validation windows",
            });
        }
        Ok(rms(&self.model.errors_at(self.data, self.validation)?))
    }
}

impl weft_sim::guard::Surrogate for InertialCorrectionMlp {
    fn name(&self) -> &str {
        KIND
    }
    fn num_dofs(&self) -> usize {
        self.linear.num_dofs()
    }
    fn scene(&self) -> Option<&str> {
        Some(self.linear.scene())
    }
    fn dt(&self) -> Option<f64> {
        Some(self.linear.dt())
    }
    fn propose(
        &mut self,
        input: &weft_sim::guard::StepInput<'_>,
    ) -> std::result::Result<Vec<f64>, weft_sim::guard::SurrogateError> {
        let q = self.linear.controls(input.prescribed)?;
        Ok(self.predict(input.previous, input.current, &q)?)
    }
}

/// The surrogate stored in the model directory `dir`, for weft-sim's guard (what `cargo
/// xtask simulate --surrogate` loads): this module's kind, or weft-surrogate's linear
/// correction through its own loader; any other kind is refused by name.
pub fn load_surrogate(dir: &Path) -> Result<Box<dyn weft_sim::guard::Surrogate>> {
    let config: serde_json::Value = crate::checkpoint::read_json(&dir.join("config.json"))?;
    match crate::checkpoint::stored_model_kind(&config) {
        Some(KIND) => Ok(Box::new(InertialCorrectionMlp::load(dir)?)),
        Some(weft_surrogate::model_dir::INERTIAL_CORRECTION) => Ok(weft_surrogate::load_surrogate(dir)?),
        other => Err(Error::Checkpoint {
            path: dir.display().to_string(),
            reason: format!(
                "holds {}, not a surrogate the guard can step (`{}` or `{KIND}`: `cargo xtask train {KIND}`)",
                other.map_or_else(|| "no model weft knows".to_string(), |k| format!("a `{k}` model")),
                weft_surrogate::model_dir::INERTIAL_CORRECTION
            ),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trainer::Silent;
    use weft_data::ClothSequence;
    use weft_sim::guard::StepInput;

    /// Frames `rest + Φ a_m` of the quick sheet in two random modes `Φ` that leave the grasp
    /// still, with `a_m = 2a_{m−1} − a_{m−2} + Δ(a_{m−1}, a_{m−1} − a_{m−2})` from rest at
    /// sequence-dependent amplitudes: the inertial residual `Φ Δ` is an exact function of
    /// the state and velocity codes, nonlinear where `Δ` is.
    fn modal_dataset(sequences: usize, frames: usize, delta: fn([f64; 2], [f64; 2]) -> [f64; 2]) -> ClothDataset {
        let scene = weft_sim::ClothScene::builtin("sheet-ms", true).unwrap();
        let mut data = ClothDataset::simulate("modal", scene, 1).unwrap();
        let rest = data.sequences[0].frame(0).to_vec();
        let grasp = data.grasp.clone();
        let mut rng = weft_sim::rng::SplitMix64::new(11);
        let mut mode = || -> Vec<f64> {
            let held = |i: usize| grasp.contains(&(i / 3));
            (0..rest.len())
                .map(|i| if held(i) { 0.0 } else { rng.uniform(-0.01, 0.01) })
                .collect()
        };
        let phi = [mode(), mode()];
        let q: Vec<f64> = grasp.iter().flat_map(|&v| rest[3 * v..3 * v + 3].to_vec()).collect();
        data.sequences = (0..sequences)
            .map(|s| {
                let t = s as f64 / sequences as f64;
                let mut a = vec![[1.6 * t - 0.8, 0.7 - 1.4 * (3.0 * t).fract()]; 2];
                while a.len() < frames + 1 {
                    let (a1, a2) = (a[a.len() - 1], a[a.len() - 2]);
                    let d = delta(a1, [a1[0] - a2[0], a1[1] - a2[1]]);
                    a.push(std::array::from_fn(|k| 2.0 * a1[k] - a2[k] + d[k]));
                }
                let positions = a[1..]
                    .iter()
                    .flat_map(|c| (0..rest.len()).map(move |i| (i, c)))
                    .map(|(i, c)| rest[i] + c[0] * phi[0][i] + c[1] * phi[1][i])
                    .collect();
                ClothSequence::new(
                    s,
                    positions,
                    q.repeat(frames),
                    vec![0; frames],
                    rest.len() / 3,
                    grasp.len(),
                )
                .unwrap()
            })
            .collect();
        data
    }

    /// A damped oscillator driven by bounded nonlinear couplings (so every sequence stays
    /// bounded) that the linear fit cannot represent.
    fn coupled(a: [f64; 2], v: [f64; 2]) -> [f64; 2] {
        [
            -0.08 * a[0] - 0.05 * v[0] + 0.04 * (4.0 * a[1]).cos(),
            -0.10 * a[1] - 0.05 * v[1] + 0.05 * (4.0 * a[0] * a[1]).tanh(),
        ]
    }

    fn tmp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("weft-icmlp-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn settings(epochs: usize) -> InertialCorrectionMlpSettings {
        InertialCorrectionMlpSettings {
            hidden: vec![64, 64],
            adam: AdamSettings {
                learning_rate: 3e-3,
                ..AdamSettings::default()
            },
            epochs,
            ..InertialCorrectionMlpSettings::default()
        }
    }

    #[test]
    fn a_residual_nonlinear_in_the_features_is_fitted_well_below_the_linear_fit() {
        let data = modal_dataset(8, 60, coupled);
        let dir = tmp("fit");
        let (model, state) = InertialCorrectionMlp::train(&dir, &data, &settings(300), &mut Silent).unwrap();
        let mlp = rms(&model.one_step_errors(&data, "test").unwrap());
        let linear = rms(&model.linear().one_step_errors(&data, "test").unwrap());
        eprintln!(
            "one-step test M_rms: MLP {mlp:.4} mm, linear {linear:.4} mm, kept epoch {}",
            state.best_epoch
        );
        assert!(
            linear > 0.01,
            "the nonlinear terms must leave the linear fit an error: {linear} mm"
        );
        assert!(mlp < 0.3 * linear, "MLP {mlp} mm against the linear fit's {linear} mm");
        let v = model.validation().unwrap();
        assert!(
            v.mlp_mm < v.linear_mm && state.best_epoch > 0,
            "{v:?}, kept epoch {}",
            state.best_epoch
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn gradients_reach_every_layer_and_the_loss_falls_from_its_start() {
        let data = modal_dataset(3, 30, coupled);
        let mut s = settings(20);
        s.base = Base::Predictor;
        let dir = tmp("grad");
        let fresh = InertialCorrectionMlp::build(
            Meta {
                kind: KIND.into(),
                settings: s.clone(),
                scale: 1.0,
                validation: None,
            },
            InertialCorrection::fit(&data, &s.linear).unwrap(),
            s.seed,
        )
        .unwrap();
        let first = |m: &InertialCorrectionMlp| -> Vec<f32> {
            m.params.vars()["layer0.w"]
                .as_tensor()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap()
        };
        let (model, state) = InertialCorrectionMlp::train(&dir, &data, &s, &mut Silent).unwrap();
        assert_ne!(first(&fresh), first(&model), "the first layer never moved");
        // The last layer starts at zero, so the starting loss is the mean squared target,
        // 1 in the scaled units (the scale is the targets' RMS per code) times the codes.
        let start = model.linear().num_codes() as f64;
        let last = state.history.last().unwrap().loss;
        assert!(last < 0.5 * start, "loss {last} from {start}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_loaded_model_proposes_the_same_frames_and_another_kind_is_refused() {
        let data = modal_dataset(3, 30, coupled);
        let dir = tmp("load");
        let (model, _) = InertialCorrectionMlp::train(&dir, &data, &settings(5), &mut Silent).unwrap();
        let loaded = InertialCorrectionMlp::load(&dir).unwrap();
        let mut surrogate = load_surrogate(&dir).unwrap();
        assert_eq!(surrogate.name(), KIND);
        let seq = &data.sequences[1];
        let prescribed: Vec<(usize, f64)> = data
            .grasp
            .iter()
            .enumerate()
            .flat_map(|(g, &v)| (0..3).map(move |k| (3 * v + k, seq.control(10)[3 * g + k])))
            .collect();
        let input = StepInput {
            frame: 10,
            dt: data.scene.dt,
            current: seq.frame(9),
            previous: seq.frame(8),
            prescribed: &prescribed,
        };
        let a = model.predict(seq.frame(8), seq.frame(9), seq.control(10)).unwrap();
        assert_eq!(a, loaded.predict(seq.frame(8), seq.frame(9), seq.control(10)).unwrap());
        assert_eq!(a, surrogate.propose(&input).unwrap());
        // The linear model's directory: refused by this loader, loaded by the dispatch.
        let linear = dir.join("linear");
        let e = InertialCorrectionMlp::load(&linear).unwrap_err().to_string();
        assert!(e.contains("`inertial-correction` model"), "{e}");
        assert_eq!(load_surrogate(&linear).unwrap().name(), "inertial-correction");
        // The network-free loader names this kind rather than misreading it.
        let e = weft_surrogate::load_surrogate(&dir).unwrap_err().to_string();
        assert!(e.contains(KIND), "{e}");
        // Another kind, and no known kind, named.
        std::fs::write(linear.join("config.json"), r#"{"material": "stvk"}"#).unwrap();
        let e = load_surrogate(&linear).unwrap_err().to_string();
        assert!(e.contains("`nnwarp` model"), "{e}");
        std::fs::write(linear.join("config.json"), "{}").unwrap();
        let e = load_surrogate(&linear).unwrap_err().to_string();
        assert!(e.contains("no model weft knows"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn bad_settings_name_their_field_and_a_changed_model_is_not_continued() {
        let mut s = settings(5);
        s.hidden = vec![32, 0];
        assert!(s.validate().unwrap_err().to_string().contains("hidden"));
        let data = modal_dataset(3, 30, coupled);
        let dir = tmp("continue");
        InertialCorrectionMlp::train(&dir, &data, &settings(2), &mut Silent).unwrap();
        // More epochs continue the run; another width does not.
        InertialCorrectionMlp::train(&dir, &data, &settings(3), &mut Silent).unwrap();
        let mut wider = settings(3);
        wider.hidden = vec![96, 64];
        let e = InertialCorrectionMlp::train(&dir, &data, &wider, &mut Silent).unwrap_err();
        assert!(e.to_string().contains("hidden"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
