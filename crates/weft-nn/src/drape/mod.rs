//! Geng et al.'s pose → cloth network with the projection layers inside training.
//!
//! - `model`: the network [`DrapeNet`], μ ([`Mu`]), the postprocessing layers and the
//!   model they make ([`DrapeModel`]), the data as tensors and the error measures;
//! - `training`: training one model of the experiment through the one
//!   [`crate::trainer::Trainer`] ([`fit`], [`load_model`]).
//!
//! There is no separate runtime: the model predicts in candle, batched.
//!
//! Everything public is re-exported here: `weft_nn::drape::X` is the one path of every
//! item.

mod model;
mod run;
mod training;

pub use model::*;
pub use run::*;
pub use training::*;
