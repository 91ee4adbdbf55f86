//! The integration tests of weft-nn, one binary (one link) for the crate.
//!
//! - `base`: layers against per-vertex loops, custom ops against finite differences of
//!   the f64 physics, the stop-gradient of Eq. 9–10, checkpoint round trips, the
//!   embedding's and NNWarp's training;
//! - `altconv`: Alt-ConvLSTM and its ConvLSTM baselines — the fused kernels and the
//!   runtime against the autograd reference;
//! - `embed_gradients`: the embedding's per-term decoder gradients against finite
//!   differences and autograd, and λ_ephys calibrated from their norms (issue 71);
//! - `embed_surrogate`: the latent simulator as a guard surrogate against the roll-out;
//! - `drape`: Geng et al.'s pose → cloth training with the projection layers;
//! - `projection_ops`: the projection layers as candle ops against finite differences.

mod altconv;
mod base;
mod drape;
mod embed_gradients;
mod embed_surrogate;
mod projection_ops;
