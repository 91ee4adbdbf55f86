//! How hard each loss term pulls on the decoder, and λ_ephys calibrated from it (issue 71).
//!
//! A loss weight sets how much a term moves the weights only through the size of the term's
//! gradient, not its value: on the mass-spring sheets `λ_ephys L_ephys` at λ = 2000 is 2–3 %
//! of stage 1's loss and every λ trains the same curves (docs/EMBEDDING.md, "Gradient norms
//! and the M_phys floor"). [`decoder_gradient_norms`] measures `‖∇_θ L_k‖` for every term
//! `L_k` of a stage, `θ` the decoder's weights (the fully connected layer and the graph
//! convolutions of `D`, which every term of stages 1 and 3 reaches), each term's gradient
//! taken over the mean of the windows given; [`calibrate_ephys`] puts `λ_ephys ‖∇L_ephys‖`
//! at a stated ratio of the largest weighted gradient among the other terms.

use super::training::{EmbedData, EmbedModel, FrameRef, LossWeights};
use crate::error::{Error, Result};

/// The prefix of the decoder's parameter names in [`EmbedModel::autoencoder_params`].
const DECODER: &str = "decoder.";

/// One loss term's gradient with respect to the decoder's weights.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TermGradient {
    /// `recon`, `vert`, `ephys`, `sim` or `mphys` (docs/EMBEDDING.md's table of losses).
    pub term: String,
    /// The term's value, the mean over the windows (`L_ephys`, `L_mphys`: scaled by the
    /// scene's `phys_scale`, as training sees them).
    pub value: f64,
    /// `‖∇_θ L_k‖`, the Euclidean norm over every decoder weight of the gradient of the
    /// term's mean over the windows.
    pub norm: f64,
    /// The term's weight λ_k in the model's configuration (λ_ephys after any warm-up).
    pub weight: f64,
    /// `λ_k ‖∇_θ L_k‖`.
    pub weighted_norm: f64,
}

/// Every term of one stage at one set of weights.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GradientNorms {
    /// 1, 2 or 3: whose loss terms.
    pub stage: u8,
    /// Windows the gradients average over.
    pub windows: usize,
    /// Decoder weights the norms run over.
    pub parameters: usize,
    pub terms: Vec<TermGradient>,
}

impl GradientNorms {
    /// The entry of `term`, if the stage has it.
    pub fn term(&self, term: &str) -> Option<&TermGradient> {
        self.terms.iter().find(|t| t.term == term)
    }
}

/// One loss term's mean over some windows and its gradient with respect to the decoder's
/// weights, flat, the parameters in name order (`decoder.conv0.b`, …, `decoder.fc.w`).
#[derive(Debug, Clone, PartialEq)]
pub struct DecoderGradient {
    pub term: &'static str,
    pub value: f64,
    pub gradient: Vec<f64>,
}

/// The gradient of every loss term of `stage` with respect to the decoder's weights, at
/// `model`'s current weights, of the term's mean over `windows` (taken in batches of the
/// configuration's size, the batch means' gradients combined by the batches' sizes).
/// Every term is evaluated, also one whose weight is 0 (a `no-pb` model's `L_ephys`): the
/// gradients do not depend on the weights. A term that does not reach the decoder
/// (`L_sim`) has a zero gradient.
pub fn decoder_gradients(
    model: &EmbedModel,
    data: &EmbedData,
    windows: &[FrameRef],
    stage: u8,
) -> Result<Vec<DecoderGradient>> {
    if windows.is_empty() || !(1..=3).contains(&stage) {
        return Err(Error::InvalidParameter {
            name: "gradient norms",
            value: format!("{} windows, stage {stage}", windows.len()),
            reason: "need at least one window and a stage of 1, 2 or 3",
        });
    }
    let decoder = decoder_parameters(model);
    let size: usize = decoder.iter().map(|v| v.elem_count()).sum();
    let every = LossWeights {
        recon: 1.0,
        vert: 1.0,
        ephys: 1.0,
        sim: 1.0,
        mphys: 1.0,
    };
    let n = windows.len() as f64;
    let mut out: Vec<DecoderGradient> = Vec::new();
    for chunk in windows.chunks(model.config.batch.max(1)) {
        let share = chunk.len() as f64 / n;
        let (_, _, graphs) = model.loss_graph(data, chunk, stage, every, None)?;
        for (k, (term, t)) in graphs.into_iter().enumerate() {
            let grads = t.backward()?;
            if out.len() == k {
                out.push(DecoderGradient {
                    term,
                    value: 0.0,
                    gradient: vec![0.0; size],
                });
            }
            let entry = &mut out[k];
            entry.value += share * t.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>()?;
            let mut at = 0;
            for var in &decoder {
                let len = var.elem_count();
                if let Some(g) = grads.get(var.as_tensor()) {
                    let g = crate::convert::tensor_to_f64("decoder gradient", g)?;
                    let acc = &mut entry.gradient[at..at + len];
                    acc.iter_mut().zip(g).for_each(|(a, g)| *a += share * g);
                }
                at += len;
            }
        }
    }
    Ok(out)
}

/// The decoder's parameters, in name order: what [`DecoderGradient::gradient`] is laid
/// out by.
pub fn decoder_parameters(model: &EmbedModel) -> Vec<&candle_core::Var> {
    model
        .autoencoder_params
        .vars()
        .iter()
        .filter(|(name, _)| name.starts_with(DECODER))
        .map(|(_, v)| v)
        .collect()
}

/// `‖∇_θ L_k‖` of every loss term of `stage` ([`decoder_gradients`]) with the weights of
/// `model`'s configuration beside them.
pub fn decoder_gradient_norms(
    model: &EmbedModel,
    data: &EmbedData,
    windows: &[FrameRef],
    stage: u8,
) -> Result<GradientNorms> {
    let weights = model.config.weights;
    let terms = decoder_gradients(model, data, windows, stage)?
        .into_iter()
        .map(|g| {
            let norm = g.gradient.iter().map(|x| x * x).sum::<f64>().sqrt();
            let weight = match g.term {
                "recon" => weights.recon,
                "vert" => weights.vert,
                "ephys" => weights.ephys,
                "sim" => weights.sim,
                _ => weights.mphys,
            };
            TermGradient {
                term: g.term.to_string(),
                value: g.value,
                norm,
                weight,
                weighted_norm: weight * norm,
            }
        })
        .collect();
    Ok(GradientNorms {
        stage,
        windows: windows.len(),
        parameters: decoder_parameters(model).iter().map(|v| v.elem_count()).sum(),
        terms,
    })
}

/// λ_ephys calibrated against the term that dominates the decoder's gradient.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EphysCalibration {
    /// The ratio asked for: `λ_ephys ‖∇L_ephys‖ = ratio · λ_d ‖∇L_d‖`.
    pub ratio: f64,
    /// The term `d` with the largest weighted gradient norm besides `L_ephys`.
    pub dominant: String,
    /// `λ_d ‖∇L_d‖`.
    pub dominant_weighted_norm: f64,
    /// `‖∇L_ephys‖`.
    pub ephys_norm: f64,
    /// The calibrated λ_ephys.
    pub ephys_weight: f64,
}

/// The λ_ephys at which `λ_ephys ‖∇_θ L_ephys‖` is `ratio` times the largest weighted
/// gradient norm `λ_k ‖∇_θ L_k‖` of the stage's other terms (under their configured
/// weights). Errors when the norms hold no `L_ephys` or no other term that pulls, when
/// `‖∇L_ephys‖` is 0, or when `ratio` is not positive and finite.
pub fn calibrate_ephys(norms: &GradientNorms, ratio: f64) -> Result<EphysCalibration> {
    if !(ratio > 0.0 && ratio.is_finite()) {
        return Err(Error::InvalidParameter {
            name: "calibration ratio",
            value: ratio.to_string(),
            reason: "must be positive and finite",
        });
    }
    let ephys = norms.term("ephys").ok_or_else(|| Error::InvalidParameter {
        name: "gradient norms",
        value: format!("stage {}", norms.stage),
        reason: "hold no L_ephys (stages 1 and 3 have it)",
    })?;
    if !(ephys.norm > 0.0 && ephys.norm.is_finite()) {
        return Err(Error::InvalidParameter {
            name: "‖∇L_ephys‖",
            value: ephys.norm.to_string(),
            reason: "must be positive and finite to calibrate against",
        });
    }
    let dominant = norms
        .terms
        .iter()
        .filter(|t| t.term != "ephys" && t.weighted_norm.is_finite())
        .max_by(|a, b| a.weighted_norm.total_cmp(&b.weighted_norm))
        .filter(|t| t.weighted_norm > 0.0)
        .ok_or_else(|| Error::InvalidParameter {
            name: "gradient norms",
            value: format!("{:?}", norms.terms.iter().map(|t| &t.term).collect::<Vec<_>>()),
            reason: "hold no other term with a non-zero weighted gradient",
        })?;
    Ok(EphysCalibration {
        ratio,
        dominant: dominant.term.clone(),
        dominant_weighted_norm: dominant.weighted_norm,
        ephys_norm: ephys.norm,
        ephys_weight: ratio * dominant.weighted_norm / ephys.norm,
    })
}
