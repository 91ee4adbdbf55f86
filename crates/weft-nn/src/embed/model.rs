//! Tan et al.'s mesh embedding (§III-B) and latent simulator (§IV-B, Eq. 7).
//!
//! - Encoder `E = F ∘ C₁ ∘ … ∘ C_L` on normalised ACAP features `[B, V, 9]`: graph
//!   convolutions that keep the 9 channels (as in the reference autoencoder), each
//!   followed by a leaky ReLU, then a fully connected layer `F` to the latent code.
//! - Decoder `D = C_Lᵀ ∘ … ∘ C₁ᵀ ∘ Fᵀ`, the mirror: a fully connected layer back to
//!   `V × 9`, then graph convolutions; the last one ends in `tanh`, because the targets
//!   are features normalised into [−0.95, 0.95] (docs/ACAP.md §A4).
//! - Latent simulator: `MLP(z_{m−2}, z_{m−1}, q_m) = z_m` with leaky-ReLU hidden layers.
//!
//! The latent code itself has no activation: a leaky ReLU there would fold half of every
//! axis onto a slope of 0.02, which the latent simulator would then have to invert.

use std::sync::Arc;

use candle_core::Tensor;

use super::fused::{DecoderOp, EncoderOp, conv_parameters};
use crate::Kernels;
use crate::error::{Error, Result};
use crate::graph::MeshGraph;
use crate::layers::{Dense, GraphConv, leaky_relu};
use crate::ops::FEATURE_CHANNELS;
use crate::params::ParamStore;

/// Shape of the autoencoder.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct AutoencoderSettings {
    /// Graph convolutions on each side, `L`.
    pub conv_layers: usize,
    /// Latent dimension (Tan et al.: 128).
    pub latent: usize,
}

impl Default for AutoencoderSettings {
    fn default() -> Self {
        Self {
            conv_layers: 2,
            latent: 128,
        }
    }
}

/// The graph-CNN mesh autoencoder.
#[derive(Debug, Clone)]
pub struct MeshAutoencoder {
    config: AutoencoderSettings,
    num_vertices: usize,
    graph: Arc<MeshGraph>,
    /// The fused encoder and decoder ops, or candle's autograd through the layers.
    kernels: Kernels,
    encoder_convs: Vec<GraphConv>,
    encoder_fc: Dense,
    decoder_fc: Dense,
    decoder_convs: Vec<GraphConv>,
}

impl MeshAutoencoder {
    pub fn new(params: &mut ParamStore, graph: Arc<MeshGraph>, config: AutoencoderSettings) -> Result<Self> {
        if config.conv_layers == 0 || config.latent == 0 {
            return Err(Error::InvalidParameter {
                name: "autoencoder config",
                value: format!("{config:?}"),
                reason: "needs at least one graph convolution and a non-empty latent code",
            });
        }
        let v = graph.num_vertices();
        let c = FEATURE_CHANNELS;
        let mut encoder_convs = Vec::new();
        let mut decoder_convs = Vec::new();
        for l in 0..config.conv_layers {
            encoder_convs.push(GraphConv::new(
                params,
                &format!("encoder.conv{l}"),
                graph.clone(),
                c,
                c,
            )?);
        }
        let encoder_fc = Dense::new(params, "encoder.fc", v * c, config.latent)?;
        let decoder_fc = Dense::new(params, "decoder.fc", config.latent, v * c)?;
        for l in 0..config.conv_layers {
            decoder_convs.push(GraphConv::new(
                params,
                &format!("decoder.conv{l}"),
                graph.clone(),
                c,
                c,
            )?);
        }
        Ok(Self {
            config,
            num_vertices: v,
            graph,
            kernels: Kernels::default(),
            encoder_convs,
            encoder_fc,
            decoder_fc,
            decoder_convs,
        })
    }

    pub fn config(&self) -> &AutoencoderSettings {
        &self.config
    }

    /// The same network computed by `kernels` (the fused ops by default).
    pub fn with_kernels(mut self, kernels: Kernels) -> Self {
        self.kernels = kernels;
        self
    }

    /// `E`: `[B, V, 9]` normalised features → `[B, latent]`.
    pub fn encode(&self, features: &Tensor) -> Result<Tensor> {
        let (b, v, c) = features.dims3()?;
        if v != self.num_vertices || c != FEATURE_CHANNELS {
            return Err(Error::Shape {
                what: "encoder input",
                expected: format!("[B, {}, {FEATURE_CHANNELS}]", self.num_vertices),
                got: format!("{:?}", features.dims()),
            });
        }
        if self.kernels == Kernels::Fused {
            let mut parts = conv_parameters(&self.encoder_convs)?;
            parts.push(self.encoder_fc.bias.flatten_all()?);
            let op = EncoderOp::new(self.graph.clone(), self.config.latent);
            return Ok(Tensor::cat(&parts, 0)?.apply_op3(&self.encoder_fc.weight, &features.contiguous()?, op)?);
        }
        let mut h = features.clone();
        for conv in &self.encoder_convs {
            h = leaky_relu(&conv.forward(&h)?)?;
        }
        self.encoder_fc.forward(&h.reshape((b, v * c))?)
    }

    /// [`MeshAutoencoder::encode`] of several batches, each `[B_k, V, 9]`. The fused
    /// encoder takes them as one batch, so the fully connected layer's 4.9 M weights (on
    /// the 4225-vertex sheet) are read once for all, not once a batch; its backward pass
    /// skips the frames that receive no gradient. Through autograd each batch is encoded
    /// alone (the reference path keeps its cost).
    pub fn encode_all(&self, batches: &[&Tensor]) -> Result<Vec<Tensor>> {
        self.through_all(batches, |x| self.encode(x))
    }

    /// [`MeshAutoencoder::decode`] of several batches of codes, as
    /// [`MeshAutoencoder::encode_all`].
    pub fn decode_all(&self, batches: &[&Tensor]) -> Result<Vec<Tensor>> {
        self.through_all(batches, |z| self.decode(z))
    }

    fn through_all(&self, batches: &[&Tensor], f: impl Fn(&Tensor) -> Result<Tensor>) -> Result<Vec<Tensor>> {
        if self.kernels != Kernels::Fused || batches.len() < 2 {
            return batches.iter().map(|&t| f(t)).collect();
        }
        let out = f(&Tensor::cat(batches, 0)?)?;
        let mut start = 0;
        let mut parts = Vec::with_capacity(batches.len());
        for t in batches {
            let rows = t.dim(0)?;
            parts.push(out.narrow(0, start, rows)?);
            start += rows;
        }
        Ok(parts)
    }

    /// `D`: `[B, latent]` → `[B, V, 9]` normalised features in (−1, 1).
    pub fn decode(&self, z: &Tensor) -> Result<Tensor> {
        Ok(self.decode_timed(z)?.0)
    }

    /// [`MeshAutoencoder::decode`] with the wall time of each layer: the fully connected
    /// one first, then each graph convolution (candle's CPU ops run eagerly, so each time
    /// is the layer's own). The fused decoder is one op: one time, the whole decoder's.
    pub fn decode_timed(&self, z: &Tensor) -> Result<(Tensor, Vec<std::time::Duration>)> {
        let (b, latent) = z.dims2()?;
        if latent != self.config.latent {
            return Err(Error::Shape {
                what: "decoder input",
                expected: format!("[B, {}]", self.config.latent),
                got: format!("{:?}", z.dims()),
            });
        }
        if self.kernels == Kernels::Fused {
            let t = std::time::Instant::now();
            let mut parts = vec![self.decoder_fc.bias.flatten_all()?];
            parts.extend(conv_parameters(&self.decoder_convs)?);
            let op = DecoderOp::new(self.graph.clone(), self.config.latent);
            let y = Tensor::cat(&parts, 0)?.apply_op3(&self.decoder_fc.weight, &z.contiguous()?, op)?;
            return Ok((y, vec![t.elapsed()]));
        }
        let mut times = Vec::with_capacity(1 + self.decoder_convs.len());
        let t = std::time::Instant::now();
        let mut h = leaky_relu(&self.decoder_fc.forward(z)?)?.reshape((b, self.num_vertices, FEATURE_CHANNELS))?;
        times.push(t.elapsed());
        let last = self.decoder_convs.len() - 1;
        for (l, conv) in self.decoder_convs.iter().enumerate() {
            let t = std::time::Instant::now();
            let y = conv.forward(&h)?;
            h = if l == last { y.tanh()? } else { leaky_relu(&y)? };
            times.push(t.elapsed());
        }
        Ok((h, times))
    }
}

/// Shape of the latent simulator.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LatentSimulatorSettings {
    pub latent: usize,
    /// Scalars of the control `q_m` (3 per grasped vertex).
    pub controls: usize,
    pub hidden: Vec<usize>,
}

/// `MLP(z_{m−2}, z_{m−1}, q_m) = z_m` (Tan et al. Eq. 7).
#[derive(Debug, Clone)]
pub struct LatentSimulator {
    config: LatentSimulatorSettings,
    layers: Vec<Dense>,
}

impl LatentSimulator {
    pub fn new(params: &mut ParamStore, config: LatentSimulatorSettings) -> Result<Self> {
        if config.latent == 0 || config.hidden.contains(&0) {
            return Err(Error::InvalidParameter {
                name: "latent simulator config",
                value: format!("{config:?}"),
                reason: "every layer needs at least one unit",
            });
        }
        let mut widths = vec![2 * config.latent + config.controls];
        widths.extend(&config.hidden);
        widths.push(config.latent);
        let layers = widths
            .windows(2)
            .enumerate()
            .map(|(l, w)| Dense::new(params, &format!("latent_sim.fc{l}"), w[0], w[1]))
            .collect::<Result<_>>()?;
        Ok(Self { config, layers })
    }

    pub fn config(&self) -> &LatentSimulatorSettings {
        &self.config
    }

    /// `z_m` from `z_{m−2}`, `z_{m−1}` (`[B, latent]`) and `q_m` (`[B, controls]`).
    pub fn step(&self, z2: &Tensor, z1: &Tensor, q: &Tensor) -> Result<Tensor> {
        let mut h = Tensor::cat(&[z2, z1, q], 1)?;
        let last = self.layers.len() - 1;
        for (l, layer) in self.layers.iter().enumerate() {
            let y = layer.forward(&h)?;
            h = if l == last { y } else { leaky_relu(&y)? };
        }
        Ok(h)
    }

    /// A roll-out of `controls.len()` frames from `z1`, `z2`: each predicted code feeds
    /// the next step (Tan et al. §V-B). Returns `[B, N, latent]`.
    pub fn rollout(&self, z1: &Tensor, z2: &Tensor, controls: &[Tensor]) -> Result<Tensor> {
        let (mut a, mut b) = (z1.clone(), z2.clone());
        let mut out = Vec::with_capacity(controls.len());
        for q in controls {
            let z = self.step(&a, &b, q)?;
            out.push(z.clone());
            (a, b) = (b, z);
        }
        Ok(Tensor::stack(&out, 1)?)
    }
}
