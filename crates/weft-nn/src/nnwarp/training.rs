//! Training NNWarp's network (§5): the node-wise pairs of a dataset, the settings, and
//! the run through the one [`crate::trainer::Trainer`].

use std::sync::Arc;

use candle_core::Tensor;
use rayon::prelude::*;
use weft_sim::warp::NodalGradients;

use super::model::{INPUTS, OUTPUTS, Standardization, WarpContext, WarpMlp, hidden_layers};
use super::runtime::NodeMlp;
use crate::error::{Error, Result};
use crate::params::ParamStore;

/// The training pairs of one split of a dataset: every free node of every frame after
/// the first (the rest frame has nothing to correct).
pub fn collect_pairs(
    dataset: &weft_data::WarpDataset,
    split: &str,
) -> Result<(Vec<[f64; INPUTS]>, Vec<[f64; OUTPUTS]>)> {
    let gradients = Arc::new(NodalGradients::new(&dataset.body)?);
    let mut inputs = Vec::new();
    let mut outputs = Vec::new();
    for s in dataset.sequences.iter().filter(|s| s.split == split) {
        // The dataset's body is already in the unit sphere: scale 1.
        let ctx = WarpContext::with_gradients(
            &dataset.body,
            gradients.clone(),
            &dataset.anchors,
            s.field,
            s.poisson,
            1.0,
        )?;
        for (lin, non) in s.linear.iter().zip(&s.nonlinear).skip(1) {
            let (x, y) = ctx.pairs(lin, non)?;
            inputs.extend(x);
            outputs.extend(y);
        }
    }
    Ok((inputs, outputs))
}

/// How an NNWarp network is trained (NNWarp §5: Adam, learning rate 1e-3, batch 1024,
/// about 10 epochs).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WarpTrainingSettings {
    /// The material the network was trained for (the dataset's array name, e.g.
    /// `neo-hookean`); set by the trainer.
    pub material: String,
    /// Hidden widths; empty means the paper's for the material ([`hidden_layers`]).
    pub hidden: Vec<usize>,
    pub adam: crate::adam::AdamSettings,
    pub batch: usize,
    pub epochs: usize,
    pub seed: u64,
    /// The learning-rate schedule and stopping rules (constant by default, as NNWarp §5).
    pub schedule: crate::trainer::Schedule,
}

impl WarpTrainingSettings {
    /// Checks every field before any work: a typed error naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        use crate::trainer::{MAX_BATCH, MAX_EPOCHS, check_adam, check_count};
        check_count("hidden (number of layers)", self.hidden.len().max(1), 64)?;
        for (i, &w) in self.hidden.iter().enumerate() {
            check_count(&format!("hidden[{i}]"), w, 4096)?;
        }
        check_count("epochs", self.epochs, MAX_EPOCHS)?;
        check_count("batch", self.batch, MAX_BATCH)?;
        check_adam("adam", &self.adam)?;
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

impl Default for WarpTrainingSettings {
    fn default() -> Self {
        Self {
            material: String::new(),
            hidden: Vec::new(),
            adam: crate::adam::AdamSettings::default(),
            batch: 1024,
            epochs: 10,
            seed: 0,
            schedule: crate::trainer::Schedule::default(),
        }
    }
}

/// Standardised pairs as `[N, 7]` and `[N, 3]` f32 tensors.
pub fn pair_tensors(
    inputs: &[[f64; INPUTS]],
    outputs: &[[f64; OUTPUTS]],
    standardization: &Standardization,
    device: &candle_core::Device,
) -> Result<(Tensor, Tensor)> {
    let x: Vec<f32> = inputs
        .iter()
        .flat_map(|r| standardization.input(r).map(|v| v as f32))
        .collect();
    let y: Vec<f32> = outputs
        .iter()
        .flat_map(|r| standardization.output(r).map(|v| v as f32))
        .collect();
    Ok((
        Tensor::from_vec(x, (inputs.len(), INPUTS), device)?,
        Tensor::from_vec(y, (outputs.len(), OUTPUTS), device)?,
    ))
}

/// Mean squared error (standardised units) of `mlp` on `x`, `y`, in chunks.
pub fn mean_loss(mlp: &WarpMlp, x: &Tensor, y: &Tensor) -> Result<f64> {
    let n = x.dim(0)?;
    if n == 0 {
        return Ok(0.0);
    }
    let mut sum = 0.0;
    let chunk = 65536;
    for start in (0..n).step_by(chunk) {
        let len = chunk.min(n - start);
        let e = (mlp.forward(&x.narrow(0, start, len)?)? - y.narrow(0, start, len)?)?;
        sum += e
            .sqr()?
            .sum_all()?
            .to_dtype(candle_core::DType::F64)?
            .to_scalar::<f64>()?;
    }
    Ok(sum / (n * OUTPUTS) as f64)
}

/// Root-mean-square error (unit-sphere units, over nodes and the three components) of
/// the runtime's correction [`NodeMlp::forward`] against the aligned targets of
/// [`WarpContext::pairs`]. Unlike the trainer's validation score (standardised units,
/// fitted on each run's own training pairs), it compares networks trained on different
/// data: the data-size study's curves use it.
pub fn correction_rms(mlp: &NodeMlp, inputs: &[[f64; INPUTS]], targets: &[[f64; OUTPUTS]]) -> Result<f64> {
    if inputs.len() != targets.len() || inputs.is_empty() {
        return Err(Error::Shape {
            what: "correction targets",
            expected: format!("{} pairs, at least one", inputs.len()),
            got: format!("{}", targets.len()),
        });
    }
    let chunk = 16384;
    let squares: f64 = inputs
        .par_chunks(chunk)
        .zip(targets.par_chunks(chunk))
        .map(|(x, y)| {
            // The runtime's correction, net(x) − net(x₀), of every pair.
            let corrections = mlp.corrections(x, &mlp.at_rest_batch(x));
            corrections
                .iter()
                .zip(y)
                .map(|(c, t)| (0..OUTPUTS).map(|d| (c[d] - t[d]).powi(2)).sum::<f64>())
                .sum::<f64>()
        })
        .sum();
    let rms = (squares / (inputs.len() * OUTPUTS) as f64).sqrt();
    if !rms.is_finite() {
        return Err(Error::NonFinite {
            what: "correction error",
            index: 0,
        });
    }
    Ok(rms)
}

/// NNWarp's MLP trained through [`crate::trainer::Trainer`] on standardised pairs: the
/// loss is the mean squared error of a batch, the validation score that of the
/// validation pairs (standardised units).
#[derive(Debug)]
pub struct WarpTraining<'a> {
    pub mlp: &'a WarpMlp,
    pub params: &'a ParamStore,
    pub x: &'a Tensor,
    pub y: &'a Tensor,
    pub validation_x: &'a Tensor,
    pub validation_y: &'a Tensor,
    pub adam: crate::adam::AdamSettings,
}

impl crate::trainer::Trainable for WarpTraining<'_> {
    fn groups(&self) -> Vec<crate::trainer::Group<'_>> {
        vec![crate::trainer::Group {
            name: "net",
            params: self.params,
            adam: self.adam,
        }]
    }

    fn num_examples(&self) -> usize {
        self.x.dim(0).unwrap_or(0)
    }

    fn batch_loss(&mut self, batch: &[usize], _at: crate::trainer::BatchAt) -> Result<crate::trainer::BatchLoss> {
        let chunk: Vec<u32> = batch.iter().map(|&i| i as u32).collect();
        let idx = Tensor::from_slice(&chunk, chunk.len(), self.x.device())?;
        let (xb, yb) = (self.x.index_select(&idx, 0)?, self.y.index_select(&idx, 0)?);
        let loss = (self.mlp.forward(&xb)? - yb)?.sqr()?.mean_all()?;
        Ok(crate::trainer::BatchLoss::Loss { loss, terms: vec![] })
    }

    fn validation_score(&mut self) -> Result<f64> {
        if self.validation_x.dim(0)? == 0 {
            return Err(Error::InvalidParameter {
                name: "validation split",
                value: "0 pairs".into(),
                reason: "model selection needs validation pairs",
            });
        }
        mean_loss(self.mlp, self.validation_x, self.validation_y)
    }
}

/// A trained model directory written by `cargo xtask train nnwarp`: `config.json` (the
/// training configuration, hidden widths resolved), `standardization.json` and the
/// trainer's run, loaded at its best validation weights.
pub fn load_model(dir: &std::path::Path) -> Result<(WarpTrainingSettings, NodeMlp)> {
    crate::checkpoint::check_model_kind(dir, "nnwarp")?;
    let read = |name: &str| -> Result<String> {
        let path = dir.join(name);
        std::fs::read_to_string(&path).map_err(|source| Error::Io {
            path: path.display().to_string(),
            source,
        })
    };
    let parse_error = |name: &str, e: serde_json::Error| Error::Checkpoint {
        path: dir.join(name).display().to_string(),
        reason: e.to_string(),
    };
    let config: WarpTrainingSettings =
        serde_json::from_str(&read("config.json")?).map_err(|e| parse_error("config.json", e))?;
    let standardization: Standardization =
        serde_json::from_str(&read("standardization.json")?).map_err(|e| parse_error("standardization.json", e))?;
    let mut params = ParamStore::new(&candle_core::Device::Cpu, config.seed);
    let mlp = WarpMlp::new(&mut params, &config.hidden, &standardization)?;
    crate::checkpoint::load_params(&dir.join("best").join("net"), &params)?;
    let node = mlp.to_node_mlp(standardization)?;
    Ok((config, node))
}

/// NNWarp's error measure `rel-error`: the mean over nodes of `|u_i − u*_i|` divided by
/// the largest reference displacement `max_i |u*_i|` (both flat `3V`). Zero when the
/// reference does not move.
pub fn rel_error(predicted: &[f64], reference: &[f64]) -> f64 {
    let n = reference.len() / 3;
    let norm = |v: &[f64], i: usize| (v[3 * i].powi(2) + v[3 * i + 1].powi(2) + v[3 * i + 2].powi(2)).sqrt();
    let max = (0..n).map(|i| norm(reference, i)).fold(0.0f64, f64::max);
    if n == 0 || max == 0.0 {
        return 0.0;
    }
    let diff: Vec<f64> = predicted.iter().zip(reference).map(|(p, r)| p - r).collect();
    (0..n).map(|i| norm(&diff, i)).sum::<f64>() / (n as f64 * max)
}

/// Trains (or continues, up to `config.epochs`) NNWarp's MLP for `dataset`'s material
/// into the model directory `dir`: `config.json` (hidden widths resolved),
/// `standardization.json` (fitted on the training pairs) and the trainer's run. The
/// validation pairs select the kept weights; the test split is not read. Returns the
/// run's state and the pair counts (training, validation).
pub fn train_model(
    dir: &std::path::Path,
    dataset: &weft_data::WarpDataset,
    config: &WarpTrainingSettings,
    observer: &mut dyn crate::trainer::Observer,
) -> Result<(crate::trainer::TrainingState, usize, usize)> {
    let mut config = config.clone();
    if !config.material.is_empty() && config.material != dataset.material {
        return Err(Error::InvalidSettings {
            field: "material".into(),
            value: config.material.clone(),
            reason: "differs from the material read from the dataset",
        });
    }
    config.material = dataset.material.clone();
    if config.hidden.is_empty() {
        config.hidden = hidden_layers(&config.material);
    }
    config.validate()?;
    let (train_x, train_y) = collect_pairs(dataset, "train")?;
    let (val_x, val_y) = collect_pairs(dataset, "validation")?;
    if train_x.is_empty() || val_x.is_empty() {
        return Err(Error::Dataset {
            path: dataset.dir.display().to_string(),
            reason: format!(
                "needs training and validation pairs (it has {} and {})",
                train_x.len(),
                val_x.len()
            ),
        });
    }
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        path: dir.display().to_string(),
        source,
    })?;
    let config_path = dir.join("config.json");
    let standardization_path = dir.join("standardization.json");
    let standardization: Standardization = if crate::trainer::has_run(dir) {
        let stored: WarpTrainingSettings = crate::checkpoint::read_json(&config_path)?;
        let stored = WarpTrainingSettings {
            epochs: config.epochs,
            ..stored
        };
        // The early-stopping patience may grow too (the trainer's rule).
        let mut same = stored.clone();
        same.schedule.early_stopping_patience = config.schedule.early_stopping_patience;
        let continues = stored.trainer().continues_as(&config.trainer()) && same == config;
        crate::checkpoint::check_continues(&config_path, continues, &stored, &config)?;
        crate::checkpoint::read_json(&standardization_path)?
    } else {
        let s = Standardization::fit(&train_x, &train_y)?;
        crate::checkpoint::write_json(&standardization_path, &s)?;
        s
    };
    crate::checkpoint::write_json(&config_path, &config)?;
    let device = candle_core::Device::Cpu;
    let (x, y) = pair_tensors(&train_x, &train_y, &standardization, &device)?;
    let (vx, vy) = pair_tensors(&val_x, &val_y, &standardization, &device)?;
    let mut params = ParamStore::new(&device, config.seed);
    let mlp = WarpMlp::new(&mut params, &config.hidden, &standardization)?;
    let mut training = WarpTraining {
        mlp: &mlp,
        params: &params,
        x: &x,
        y: &y,
        validation_x: &vx,
        validation_y: &vy,
        adam: config.adam,
    };
    let trainer = crate::trainer::Trainer::new(format!("nnwarp/{}", config.material), config.trainer());
    let state = trainer.run(dir, &mut training, observer)?;
    Ok((state, train_x.len(), val_x.len()))
}
