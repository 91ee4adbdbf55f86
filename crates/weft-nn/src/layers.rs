//! Layers: Tan et al.'s graph convolution and a dense layer.

use std::sync::Arc;

use candle_core::Tensor;

use crate::error::Result;
use crate::graph::MeshGraph;
use crate::params::{Init, ParamStore};

/// The slope of every leaky ReLU in weft's networks.
pub const LEAKY_SLOPE: f64 = 0.02;

pub fn leaky_relu(x: &Tensor) -> Result<Tensor> {
    Ok(candle_nn::ops::leaky_relu(x, LEAKY_SLOPE)?)
}

/// Tan et al.'s graph convolution (§III-B):
/// `C(x)_i = M x_i + M_N · mean_{j ∈ N¹(i)} x_j + b`, on `[B, V, C_in]` → `[B, V, C_out]`.
/// One neighbour mean and two matrix products per call, for all vertices at once. The
/// weights do not depend on the vertex count.
#[derive(Debug, Clone)]
pub struct GraphConv {
    graph: Arc<MeshGraph>,
    pub(crate) self_weight: Tensor,
    pub(crate) neighbor_weight: Tensor,
    pub(crate) bias: Tensor,
}

impl GraphConv {
    pub fn new(params: &mut ParamStore, name: &str, graph: Arc<MeshGraph>, c_in: usize, c_out: usize) -> Result<Self> {
        // Two inputs of fan-in c_in each feed every output.
        let init = Init::kaiming(2 * c_in, LEAKY_SLOPE);
        Ok(Self {
            graph,
            self_weight: params.create(&format!("{name}.m"), &[c_in, c_out], init)?,
            neighbor_weight: params.create(&format!("{name}.m_n"), &[c_in, c_out], init)?,
            bias: params.create(&format!("{name}.b"), &[c_out], Init::Zeros)?,
        })
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mean = self.graph.neighbor_mean(x)?;
        let y = x.broadcast_matmul(&self.self_weight)? + mean.broadcast_matmul(&self.neighbor_weight)?;
        Ok(y?.broadcast_add(&self.bias)?)
    }
}

/// `x W + b` on the last dimension.
#[derive(Debug, Clone)]
pub struct Dense {
    pub(crate) weight: Tensor,
    pub(crate) bias: Tensor,
}

impl Dense {
    pub fn new(params: &mut ParamStore, name: &str, c_in: usize, c_out: usize) -> Result<Self> {
        Ok(Self {
            weight: params.create(&format!("{name}.w"), &[c_in, c_out], Init::kaiming(c_in, LEAKY_SLOPE))?,
            bias: params.create(&format!("{name}.b"), &[c_out], Init::Zeros)?,
        })
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        Ok(x.broadcast_matmul(&self.weight)?.broadcast_add(&self.bias)?)
    }
}
