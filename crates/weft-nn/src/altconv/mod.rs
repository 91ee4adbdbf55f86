//! Alt-ConvLSTM (seed 001, §4) and the vanilla graph ConvLSTM baselines it is compared
//! with (§5.2), on a surface mesh in vertex correspondence over time.
//!
//! Every convolution is the graph convolution of Eq. 9, `Â_n X Θ` with the Kipf–Welling
//! normalised adjacency ([`crate::graph::NormalizedAdjacency`]). Because `Â_n (X Θ) = (Â_n X) Θ`, a cell
//! multiplies each of its inputs by `Â_n` once and then runs one dense product per input
//! for all four gates together: a few large operations per layer, and weights whose size
//! depends only on the channel counts, never on the vertex count.
//!
//! The Alt-ConvLSTM cell is Eq. 5:
//! ```text
//! i_t = σ(W_xi∗X_t + W_hi∗H_{t−1} + W_ci∗Y_{t−1} + b_i)
//! f_t = σ(W_xf∗X_t + W_hf∗H_{t−1} + W_cf∗Y_{t−1} + b_f)
//! C_t = f_t∘C_{t−1} + i_t∘tanh(W_xc∗X_t + W_hc∗H_{t−1} + b_c)
//! Y_t = Y_{t−1} + C_t                      (+ C_t^{l−m}, the skip of Eq. 10)
//! o_t = σ(W_xo∗X_t + W_ho∗H_{t−1} + W_co∗Y_t + b_o)
//! H_t = o_t∘tanh(C_t)
//! ```
//! The vanilla ConvLSTM has no `Y`: its convolutional peepholes (CP) look at `C_{t−1}` and
//! `C_t`, or it has none (NP).
//!
//! The network (§4.3, §5.1): five hidden cells of 32-64-128-64-32 channels and a
//! 3-channel output cell, the input of cell `l` being the cell state `C^{l−1}` of the one
//! below. The input of the first is `[X_t, X_t − X_{t−1}, Y₀ − X₀]` (9 channels).
//! - **Alt-ConvLSTM**: Eq. 10's skips join equal-width layers across the bottleneck (the
//!   second 64-channel cell takes the first's `C`, the second 32-channel cell the first's);
//!   the output cell's accumulation is the prediction, `Ŷ_t = Y_{t−1}^out + C_t^out +
//!   (X_t − X_{t−1})` (Eq. 11), started from `Y_0^out = Y_0`, `C_0^out = 0`.
//! - **ConvLSTM-…-ΔY**: `C^out` is a velocity, `Ŷ_t = Ŷ_{t−1} + C_t^out + (X_t − X_{t−1})`.
//! - **ConvLSTM-…-Y**: `C^out` is the position, read with the same input-to-output skip as
//!   an offset from the pose: `Ŷ_t = X_t + C_t^out`, started from `C_0^out = Y_0 − X_0`.
//!
//! Teacher forcing (§5.1) replaces the previous prediction by the truth: `Y_{t−1}^out`
//! (Alt-ConvLSTM), `Ŷ_{t−1}` (ΔY) or `C_{t−1}^out = Y_{t−1} − X_{t−1}` (Y). It is how the
//! models train and what the single-step error measures; a roll-out feeds back its own
//! predictions. The loss is Eq. 12, the mean Euclidean vertex error.
//!
//! Training and evaluation run in candle; [`AltConvRuntime`] rolls a trained model out
//! without it, for speed.
//!
//! - `model`: the cells and the network in candle, the autograd reference;
//! - `cell`: each cell's gate layout and elementwise equations over f32 slices, written
//!   once for the fused kernels and the runtime;
//! - `fused`: a whole teacher-forced sequence and its backward pass as one candle op;
//! - `training`: [`AltConvTrainingSettings`], [`train_model`], [`score_sequence`];
//! - `runtime`: [`AltConvRuntime`], the roll-out outside candle;
//! - `diagnostics`: [`diagnose`], the gates, states and gradients of a roll-out (issue 69).
//!
//! Everything public is re-exported here: `weft_nn::altconv::X` is the one path of every
//! item.

mod cell;
mod diagnostics;
mod fused;
mod model;
mod runtime;
mod summary;
mod training;

pub use crate::Kernels;
pub use diagnostics::*;
pub use fused::FusedWorkspace;
pub use model::*;
pub use runtime::AltConvRuntime;
pub use summary::*;
pub use training::*;
