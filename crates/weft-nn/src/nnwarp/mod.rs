//! NNWarp (Luo et al.): the node-wise correction MLP that turns a linear FEM displacement
//! into the nonlinear material's.
//!
//! Everything public is re-exported here: `weft_nn::nnwarp::X` is the one path of every
//! item.

mod model;

pub use model::*;
