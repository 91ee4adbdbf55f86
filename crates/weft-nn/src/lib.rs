//! Neural models of weft, on candle — the only crate of the workspace that touches it.
//!
//! **The four models** share one layout: each is a folder with `model.rs` (the network
//! in candle), `training.rs` (its settings, data and the run through [`trainer`]) and,
//! where one exists, `runtime.rs` (the trained model used outside training) and
//! `fused.rs` (fused kernels with hand-written backward passes, the default
//! [`Kernels`]). The files are private; every public item has one path at the folder's
//! root (`weft_nn::embed::train_model`, `weft_nn::altconv::AltConvRuntime`).
//! - [`embed`]: Tan et al.'s graph-CNN mesh autoencoder and latent simulator (Eq. 7), its
//!   three training stages and the latent roll-out;
//! - [`nnwarp`]: NNWarp's node-wise correction MLP — training pairs from registered
//!   sequences, training in candle, and a runtime over the trained weights outside it;
//! - [`drape`]: Geng et al.'s pose → cloth network with the projection layers inside
//!   training (a fixed, learned global or learned per-vertex μ);
//! - [`altconv`]: Alt-ConvLSTM and its graph ConvLSTM baselines for soft-tissue dynamics —
//!   the cells on the Kipf–Welling normalised adjacency
//!   ([`graph::NormalizedAdjacency`]), teacher-forced training, and a roll-out runtime
//!   outside candle; the cells' elementwise equations are written once (`altconv/cell.rs`)
//!   for the fused kernels and the runtime.
//!
//! **Beside the models:**
//! - [`pca_simulator`]: the embedding's latent MLP on a PCA subspace ([`pca`]) — the
//!   linear baseline for reduced simulation;
//! - [`inertial_correction`]: a learned one-step surrogate for weft-sim's guard — the
//!   inertial predictor plus a ridge-regressed correction in a PCA subspace of its
//!   residuals, fitted in closed form; it and [`pca`] are weft-surrogate's, re-exported,
//!   so what steps a scene under the guard needs no candle;
//! - [`inertial_correction_mlp`]: its nonlinear version — an MLP on the same features
//!   adding to the linear correction's codes, trained through [`trainer`] — and the loader
//!   of either kind as a guard surrogate;
//! - [`ik`]: cloth inverse kinematics in the embedding's latent space (Tan et al. §V-A)
//!   beside the same potential minimised over every vertex;
//! - [`metrics`]: the error measures the experiments report (M_RMS, STED, nDCG).
//!
//! **Blocks every model is built from** (the models import these, never each other, but
//! for [`pca_simulator`] and [`ik`] on [`embed`]):
//! - [`graph`], [`layers`]: a mesh's 1-ring graph as tensors and Tan et al.'s graph
//!   convolution `M x_i + M_N · mean_{j∈N¹(i)} x_j + b`, a few large tensor operations per
//!   layer, with weights independent of the vertex count;
//! - [`ops`]: the physics as custom ops with hand-written backward passes — ACAP⁻¹ through
//!   weft-acap's pre-factorised Poisson solve and its vector–Jacobian product, and
//!   L_phys (Eq. 4) through weft-sim's energies, with the gradient into the two previous
//!   frames stopped (Eq. 9–10), the elastic potential `P_s + P_b`, and Geng et al.'s
//!   inextensibility and quasistatic projections through weft-proj's backward passes;
//! - [`trainer`]: the one training loop every model runs through — epochs, batches, Adam
//!   per parameter group, learning-rate schedules, gradient clipping, model selection and
//!   early stopping on the validation split only, a checkpoint each epoch and
//!   bit-identical resume;
//! - seeded parameters ([`params::ParamStore`]), Adam with checkpointable state
//!   ([`adam`]), resumable checkpoints ([`checkpoint`]), the one f32 ↔ f64 boundary
//!   ([`convert`]) and the vectorised f32 activations of the runtimes ([`fast`]).
//!
//! **What a training command settles**, so the command line only parses and prints:
//! [`train_setup`] (the configuration file or default, the overrides every command takes,
//! the refusal to overwrite a model, altconv's window fitted to the data), [`train_job`]
//! (each model's run from flags to the lines it reports), [`config_help`] (the
//! configuration files' help text) and [`progress`] (a run's bar and epoch lines, an
//! observer of the trainer).
//!
//! **Conventions:** configuration types are `*Settings` (their serialised field names are
//! the model directories' `config.json`); one [`Error`], `#[non_exhaustive]`, with
//! `Result<T, E = Error>`.
//!
//! What is not here: no physics or geometry of its own (every formula of the simulation
//! lives in weft-sim, weft-acap or weft-proj and is called, never re-derived in
//! tensors), no file formats beyond checkpoints and model directories (datasets are
//! weft-data's), no command line (that is xtask's), no experiment (that is
//! weft-experiments').
//!
//! Precision: networks run in f32; everything that crosses into the physics is converted
//! to f64 and checked for NaN at that boundary.
//!
//! ```
//! use std::sync::Arc;
//! use candle_core::{Device, Tensor};
//! use weft_nn::{embed::{AutoencoderSettings, MeshAutoencoder}, graph::MeshGraph, params::ParamStore};
//! let sheet = weft_mesh::generators::sheet(5, 1.0)?;
//! let graph = Arc::new(MeshGraph::new(&sheet, &Device::Cpu)?);
//! let mut params = ParamStore::new(&Device::Cpu, 42);
//! let config = AutoencoderSettings { conv_layers: 1, latent: 8 };
//! let model = MeshAutoencoder::new(&mut params, graph, config)?;
//! let features = Tensor::zeros((2, 25, 9), candle_core::DType::F32, &Device::Cpu)?;
//! let z = model.encode(&features)?;
//! assert_eq!(z.dims(), &[2, 8]);
//! assert_eq!(model.decode(&z)?.dims(), &[2, 25, 9]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod adam;
pub mod altconv;
pub mod checkpoint;
pub mod config_help;
pub mod convert;
pub mod drape;
pub mod embed;
pub mod error;
pub mod fast;
pub mod graph;
pub mod ik;
pub mod inertial_correction_mlp;
pub mod layers;
pub mod metrics;
pub mod nnwarp;
pub mod ops;
pub mod params;
pub mod pca_simulator;
pub mod progress;
pub mod train_job;
pub mod train_setup;
pub mod trainer;

pub use candle_core::Device;
pub use error::{Error, Result};
/// The closed-form surrogates live below this crate (weft-surrogate, no candle) and keep
/// their paths here.
pub use weft_surrogate::{inertial_correction, pca};

/// Which implementation computes a model's training passes: the fused kernels with
/// hand-written backward passes, or candle's autograd through the same model built from
/// tensor operations — the reference the kernels are tested against. The mathematics is
/// the same; the results agree to f32 round-off (tested per model).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kernels {
    #[default]
    Fused,
    Autograd,
}
