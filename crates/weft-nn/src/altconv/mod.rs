//! Alt-ConvLSTM and its graph ConvLSTM baselines.
//!
//! Everything public is re-exported here: `weft_nn::altconv::X` is the one path of every
//! item.

mod fused;
mod model;
mod runtime;

pub use fused::FusedWorkspace;
pub use model::*;
pub use runtime::AltConvRuntime;
