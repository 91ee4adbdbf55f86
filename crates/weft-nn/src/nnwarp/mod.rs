//! NNWarp (Luo et al.): the node-wise correction MLP that turns a linear FEM displacement
//! into the nonlinear material's.
//!
//! - `model`: the per-node inputs ([`WarpContext`], [`NodeInputs`]), their
//!   standardisation and the network in candle ([`WarpMlp`]);
//! - `runtime`: the same weights outside candle ([`NodeMlp`]), the correction of a linear
//!   solution ([`NnWarp`]) and the corrected linear simulation ([`NnWarpSimulation`]);
//! - `surrogate`: NNWarp and the linear solves as proposals of a guarded quasistatic
//!   load step ([`WarpSurrogate`]);
//! - `training`: the training pairs of a dataset, [`WarpTrainingSettings`] and
//!   [`train_model`].
//!
//! Everything public is re-exported here: `weft_nn::nnwarp::X` is the one path of every
//! item.

mod model;
mod reference;
mod run;
mod runtime;
mod scene;
mod surrogate;
mod training;

pub use model::*;
pub use reference::*;
pub use run::*;
pub use runtime::*;
pub use scene::*;
pub use surrogate::*;
pub use training::*;
