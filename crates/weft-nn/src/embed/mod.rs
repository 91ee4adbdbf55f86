//! Tan et al.'s mesh embedding and latent simulator: the model, its three-stage training
//! and its roll-out.
//!
//! - `model`: the graph-CNN autoencoder [`MeshAutoencoder`] (§III-B) and the latent
//!   simulator [`LatentSimulator`] (§IV-B, Eq. 7);
//! - `fused`: the autoencoder's encoder and decoder as two fused candle ops with
//!   hand-written backward passes (the model's default [`crate::Kernels`]);
//! - `training`: the three training stages (§VI-A) on a cloth dataset ([`EmbedData`],
//!   [`EmbedModel`], [`train_model`]);
//! - `runtime`: the latent roll-out simulation (§V-B, [`LatentRollout`]);
//! - `surrogate`: the latent simulator one step at a time from accepted frames, as a
//!   surrogate of weft-sim's guard ([`EmbedSurrogate`], docs/GUARD.md);
//! - `gradients`: each loss term's gradient norm on the decoder and λ_ephys calibrated
//!   from them ([`decoder_gradient_norms`], [`calibrate_ephys`]; issue 71).
//!
//! Everything public is re-exported here: `weft_nn::embed::X` is the one path of every
//! item; the files are how the code is read, not part of the API.

mod fused;
mod gradients;
mod model;
mod runtime;
mod surrogate;
mod training;

pub use gradients::*;
pub use model::*;
pub use runtime::*;
pub use surrogate::*;
pub use training::*;
