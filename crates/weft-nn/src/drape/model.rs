//! Geng et al.'s pose → cloth network with physics postprocesses in training (§2–6):
//! a network maps the joint angles θ to per-vertex offsets `d(θ)` added to the kinematic
//! guess, `r̂ = r̃(θ) + d(θ)` (Geng et al. Eq. in §2, after Jin et al.), and an optional
//! projection layer maps `r̂` to `r*` ([`ops::InextensibilityProjection`] or
//! [`ops::QuasistaticProjection`]). Training minimises `Σ ‖r* − r_T‖²` (§4, §6), so the
//! network learns what the layer does to its output.
//!
//! The network is the same for every method: a small MLP (the issue allows an MLP in
//! place of Jin et al.'s image CNN), leaky-ReLU hidden layers and a linear output scaled
//! by `offset_scale` (m), so the output layer's weights are of order one.
//!
//! μ of the quasistatic layer is either fixed or learned, as one global value or one per
//! vertex (Eq. 15–16). A learned μ is parameterised by `log μ`, which keeps it positive
//! (weft-proj rejects μ ≤ 0) and makes a step of Adam a relative change of μ; it has its
//! own parameter set so it can take its own learning rate.

use candle_core::{DType, Device, Tensor};

use crate::error::{Error, Result};
use crate::layers::{Dense, leaky_relu};
use crate::ops::{InextensibilityProjection, QuasistaticProjection};
use crate::params::{Init, ParamStore};
pub use weft_sim::scenes::drape::POSE_ANGLES;

/// Shape of [`DrapeNet`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DrapeNetSettings {
    /// Widths of the hidden layers.
    pub hidden: Vec<usize>,
    /// The output is `offset_scale · (x W + b)` metres.
    pub offset_scale: f64,
}

impl Default for DrapeNetSettings {
    fn default() -> Self {
        Self {
            hidden: vec![64, 256],
            offset_scale: 0.01,
        }
    }
}

/// θ `[B, POSE_ANGLES]` → offsets `d` `[B, V, 3]` (m).
#[derive(Debug, Clone)]
pub struct DrapeNet {
    hidden: Vec<Dense>,
    out: Dense,
    scale: f64,
    num_vertices: usize,
}

impl DrapeNet {
    pub fn new(params: &mut ParamStore, config: &DrapeNetSettings, num_vertices: usize) -> Result<Self> {
        if config.hidden.is_empty() || config.hidden.contains(&0) || !(config.offset_scale > 0.0) {
            return Err(Error::InvalidParameter {
                name: "drape network shape",
                value: format!("hidden {:?}, offset scale {}", config.hidden, config.offset_scale),
                reason: "needs non-empty, non-zero hidden widths and a positive offset scale",
            });
        }
        let mut hidden = Vec::with_capacity(config.hidden.len());
        let mut c_in = POSE_ANGLES;
        for (k, &w) in config.hidden.iter().enumerate() {
            hidden.push(Dense::new(params, &format!("hidden{k}"), c_in, w)?);
            c_in = w;
        }
        let out = Dense::new(params, "out", c_in, 3 * num_vertices)?;
        Ok(Self {
            hidden,
            out,
            scale: config.offset_scale,
            num_vertices,
        })
    }

    pub fn num_vertices(&self) -> usize {
        self.num_vertices
    }

    /// The offsets `d(θ)` for poses `[B, POSE_ANGLES]` (rad), `[B, V, 3]` in metres.
    pub fn offsets(&self, pose: &Tensor) -> Result<Tensor> {
        let (b, angles) = pose.dims2()?;
        if angles != POSE_ANGLES {
            return Err(Error::Shape {
                what: "drape network input",
                expected: format!("[B, {POSE_ANGLES}] joint angles"),
                got: format!("{:?}", pose.dims()),
            });
        }
        let mut x = pose.clone();
        for layer in &self.hidden {
            x = leaky_relu(&layer.forward(&x)?)?;
        }
        Ok((self.out.forward(&x)? * self.scale)?.reshape((b, self.num_vertices, 3))?)
    }
}

/// μ of the quasistatic layer.
#[derive(Debug, Clone)]
pub enum Mu {
    /// A fixed global μ.
    Fixed(f64),
    /// A learned `log μ`: shape `[1]` (global) or `[V]` (per vertex).
    Learned(Tensor),
}

impl Mu {
    /// A learned μ starting at `start` everywhere, in `params` under `mu.log`.
    pub fn learned(params: &mut ParamStore, start: f64, per_vertex: Option<usize>) -> Result<Self> {
        if !(start > 0.0 && start.is_finite()) {
            return Err(Error::InvalidParameter {
                name: "learned mu start",
                value: start.to_string(),
                reason: "must be positive and finite",
            });
        }
        let n = per_vertex.unwrap_or(1);
        Ok(Self::Learned(params.create(
            "mu.log",
            &[n],
            Init::Constant(start.ln()),
        )?))
    }

    /// μ as a tensor (`[1]` or `[V]`).
    pub fn value(&self, device: &Device) -> Result<Tensor> {
        Ok(match self {
            Self::Fixed(mu) => Tensor::new(&[*mu as f32], device)?,
            Self::Learned(log_mu) => log_mu.exp()?,
        })
    }
}

/// What follows the network.
#[derive(Debug, Clone)]
pub enum Postprocess {
    None,
    Inextensibility(InextensibilityProjection),
    Quasistatic { op: QuasistaticProjection, mu: Mu },
}

/// The network and its postprocess.
#[derive(Debug, Clone)]
pub struct DrapeModel {
    pub net: DrapeNet,
    pub post: Postprocess,
}

impl DrapeModel {
    /// `r̂ = r̃ + d(θ)` for poses `[B, POSE_ANGLES]` and guesses `[B, V, 3]` (m).
    pub fn network_output(&self, pose: &Tensor, guess: &Tensor) -> Result<Tensor> {
        Ok((guess + self.net.offsets(pose)?)?)
    }

    /// `r*`: the postprocess applied to [`DrapeModel::network_output`].
    pub fn predict(&self, pose: &Tensor, guess: &Tensor) -> Result<Tensor> {
        self.predict_keyed(pose, guess, None)
    }

    /// [`predict`](Self::predict) naming the examples (their indices in the training set),
    /// so either layer warm-starts each from its previous solution.
    pub fn predict_keyed(&self, pose: &Tensor, guess: &Tensor, keys: Option<&[usize]>) -> Result<Tensor> {
        let r_hat = self.network_output(pose, guess)?;
        match (&self.post, keys) {
            (Postprocess::None, _) => Ok(r_hat),
            (Postprocess::Inextensibility(op), None) => op.apply(&r_hat),
            (Postprocess::Inextensibility(op), Some(k)) => op.apply_keyed(&r_hat, k),
            (Postprocess::Quasistatic { op, mu }, None) => op.apply(&r_hat, &mu.value(r_hat.device())?),
            (Postprocess::Quasistatic { op, mu }, Some(k)) => op.apply_keyed(&r_hat, &mu.value(r_hat.device())?, k),
        }
    }
}

/// Geng et al.'s training energy per example, in mm²: the mean over the batch of
/// `Σ_i ‖r*_i − r_T,i‖² / V` (the square of SqrtMSE), so its scale does not depend on
/// the mesh size.
pub fn loss(prediction: &Tensor, truth: &Tensor) -> Result<Tensor> {
    let (_, v, _) = truth.dims3()?;
    let d = ((prediction - truth)? * 1e3)?;
    Ok((d.sqr()?.sum_all()? / (v * prediction.dim(0)?) as f64)?)
}

/// Poses, guesses and truths of a set of examples as f32 tensors.
#[derive(Debug, Clone)]
pub struct DrapeTensors {
    pub pose: Tensor,
    pub guess: Tensor,
    pub truth: Tensor,
}

impl DrapeTensors {
    /// From flat f64 arrays: poses `POSE_ANGLES·N`, guesses and truths `3VN` (m).
    pub fn new(pose: &[f64], guess: &[f64], truth: &[f64], num_vertices: usize, device: &Device) -> Result<Self> {
        let n = pose.len() / POSE_ANGLES;
        if pose.len() != POSE_ANGLES * n || guess.len() != 3 * num_vertices * n || truth.len() != guess.len() || n == 0
        {
            return Err(Error::Shape {
                what: "drape examples",
                expected: format!("{POSE_ANGLES}N pose values and 3·{num_vertices}·N guess and truth values, N ≥ 1"),
                got: format!("{}, {} and {}", pose.len(), guess.len(), truth.len()),
            });
        }
        let t = |what: &'static str, x: &[f64], shape: &[usize]| -> Result<Tensor> {
            let f = crate::convert::f64_to_f32(what, x)?;
            Ok(Tensor::from_vec(f, shape, device)?)
        };
        Ok(Self {
            pose: t("drape poses", pose, &[n, POSE_ANGLES])?,
            guess: t("drape guesses", guess, &[n, num_vertices, 3])?,
            truth: t("drape truths", truth, &[n, num_vertices, 3])?,
        })
    }

    /// The examples of one split of a `drape` dataset (f32, metres).
    pub fn of_split(dataset: &weft_data::DrapeDataset, split: &str, device: &Device) -> Result<Self> {
        let chosen: Vec<&weft_data::DrapeExample> = dataset.split(split).collect();
        let pose: Vec<f64> = chosen.iter().flat_map(|e| e.pose).collect();
        let guess: Vec<f64> = chosen.iter().flat_map(|e| e.guess.iter().copied()).collect();
        let truth: Vec<f64> = chosen.iter().flat_map(|e| e.truth.iter().copied()).collect();
        Self::new(&pose, &guess, &truth, dataset.sleeve.num_vertices(), device)
    }

    pub fn len(&self) -> usize {
        self.pose.dim(0).unwrap_or(0)
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Every example's pose, flat `POSE_ANGLES·N` f64 (rad).
    pub fn poses(&self) -> Result<Vec<f64>> {
        Ok(self.pose.to_dtype(DType::F64)?.flatten_all()?.to_vec1::<f64>()?)
    }

    /// Every example's truth, flat f64 (m).
    pub fn truths(&self) -> Result<Vec<Vec<f64>>> {
        let t = self.truth.to_dtype(DType::F64)?;
        (0..self.len())
            .map(|k| Ok(t.get(k)?.flatten_all()?.to_vec1::<f64>()?))
            .collect()
    }

    /// The examples at `indices`.
    pub fn select(&self, indices: &[usize]) -> Result<Self> {
        let idx = Tensor::from_vec(
            indices.iter().map(|&i| i as u32).collect::<Vec<_>>(),
            indices.len(),
            self.pose.device(),
        )?;
        Ok(Self {
            pose: self.pose.index_select(&idx, 0)?,
            guess: self.guess.index_select(&idx, 0)?,
            truth: self.truth.index_select(&idx, 0)?,
        })
    }
}

impl DrapeModel {
    /// μ of a learned-μ quasistatic postprocess (the global value, or one per vertex);
    /// `None` for any other postprocess.
    pub fn learned_mu(&self) -> Result<Option<Vec<f64>>> {
        Ok(match &self.post {
            Postprocess::Quasistatic {
                mu: mu @ Mu::Learned(_),
                ..
            } => Some(
                mu.value(&Device::Cpu)?
                    .to_vec1::<f32>()?
                    .into_iter()
                    .map(f64::from)
                    .collect(),
            ),
            _ => None,
        })
    }
}

/// `r*` of every example, in batches, as flat f64 per example (m).
pub fn predict_all(model: &DrapeModel, data: &DrapeTensors, batch: usize) -> Result<Vec<Vec<f64>>> {
    predict_each(model, data, batch)?
        .into_iter()
        .map(|r| {
            r.map_err(|e| Error::InvalidParameter {
                name: "drape prediction",
                value: e,
                reason: "the postprocess failed",
            })
        })
        .collect()
}

/// `r*` of every example as flat f64 (m), or the postprocess's error for an example it
/// failed on: a failing batch is retried example by example, so one bad example does not
/// take its batch with it. Every layer solve starts cold.
pub fn predict_each(
    model: &DrapeModel,
    data: &DrapeTensors,
    batch: usize,
) -> Result<Vec<std::result::Result<Vec<f64>, String>>> {
    predict_each_from(model, data, batch, None)
}

/// [`predict_each`] with example `i` keyed `first_key + i`, so each layer solve starts from
/// that key's previous solution (training's per-epoch validation pass: the same 200
/// examples every epoch, under weights that changed by one epoch). Keys must not collide
/// with the training examples' (`0..n_train`), which share the layers' warm-start store.
pub fn predict_each_keyed(
    model: &DrapeModel,
    data: &DrapeTensors,
    batch: usize,
    first_key: usize,
) -> Result<Vec<std::result::Result<Vec<f64>, String>>> {
    predict_each_from(model, data, batch, Some(first_key))
}

fn predict_each_from(
    model: &DrapeModel,
    data: &DrapeTensors,
    batch: usize,
    first_key: Option<usize>,
) -> Result<Vec<std::result::Result<Vec<f64>, String>>> {
    let n = data.len();
    let mut out = Vec::with_capacity(n);
    let idx: Vec<usize> = (0..n).collect();
    let rows = |r: Tensor, k: usize| -> Result<Vec<std::result::Result<Vec<f64>, String>>> {
        let r = r.to_dtype(DType::F64)?;
        (0..k)
            .map(|i| Ok(Ok(r.get(i)?.flatten_all()?.to_vec1::<f64>()?)))
            .collect()
    };
    let keys = |chunk: &[usize]| first_key.map(|k0| chunk.iter().map(|i| k0 + i).collect::<Vec<_>>());
    for chunk in idx.chunks(batch.max(1)) {
        let b = data.select(chunk)?;
        match model.predict_keyed(&b.pose, &b.guess, keys(chunk).as_deref()) {
            Ok(r) => out.extend(rows(r, chunk.len())?),
            Err(_) => {
                for &i in chunk {
                    let one = data.select(&[i])?;
                    match model.predict_keyed(&one.pose, &one.guess, keys(&[i]).as_deref()) {
                        Ok(r) => out.extend(rows(r, 1)?),
                        Err(e) => out.push(Err(e.to_string())),
                    }
                }
            }
        }
    }
    Ok(out)
}

/// Geng et al.'s per-example errors (mm): SqrtMSE `sqrt(Σ_i ‖r_i − r_T,i‖² / V)` and
/// MaxDist `max_i ‖r_i − r_T,i‖` (docs/DRAPE.md; per-vertex normalisation).
pub fn sqrtmse_maxdist_mm(prediction: &[f64], truth: &[f64]) -> Result<(f64, f64)> {
    if prediction.len() != truth.len() || prediction.is_empty() || !prediction.len().is_multiple_of(3) {
        return Err(Error::Shape {
            what: "drape error",
            expected: format!("{} coordinates", truth.len()),
            got: format!("{}", prediction.len()),
        });
    }
    let (mut sum, mut max) = (0.0f64, 0.0f64);
    for (p, t) in prediction.chunks_exact(3).zip(truth.chunks_exact(3)) {
        let d2 = (p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2) + (p[2] - t[2]).powi(2);
        sum += d2;
        max = max.max(d2);
    }
    let v = (prediction.len() / 3) as f64;
    Ok((1e3 * (sum / v).sqrt(), 1e3 * max.sqrt()))
}
