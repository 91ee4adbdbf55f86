//! A mesh's 1-ring graph as tensors, built once per mesh, and the neighbour mean of Tan et
//! al.'s graph convolution as three large tensor operations.

use candle_core::{DType, Device, Tensor};
use weft_mesh::{Topology, TriMesh};

use crate::error::{Error, Result};

/// The directed 1-ring edges of a mesh (`src` → `dst` for every neighbour pair, both ways)
/// and each vertex's inverse degree.
#[derive(Debug, Clone)]
pub struct MeshGraph {
    num_vertices: usize,
    src: Tensor,
    dst: Tensor,
    /// `1/|N¹(i)|` as a `[1, V, 1]` f32 tensor (0 for an isolated vertex).
    inv_degree: Tensor,
}

impl MeshGraph {
    /// The 1-ring graph of `mesh` (vertices sharing an edge).
    pub fn new(mesh: &TriMesh, device: &Device) -> Result<Self> {
        let topo = Topology::new(mesh);
        Self::from_edges(mesh.num_vertices(), &topo.edges, device)
    }

    /// The graph of undirected `edges` over `num_vertices` vertices.
    pub fn from_edges(num_vertices: usize, edges: &[[usize; 2]], device: &Device) -> Result<Self> {
        let mut src = Vec::with_capacity(2 * edges.len());
        let mut dst = Vec::with_capacity(2 * edges.len());
        let mut degree = vec![0u32; num_vertices];
        for &[a, b] in edges {
            if a >= num_vertices || b >= num_vertices || a == b {
                return Err(Error::InvalidParameter {
                    name: "graph edge",
                    value: format!("[{a}, {b}]"),
                    reason: "needs two distinct vertices below the vertex count",
                });
            }
            src.extend([a as u32, b as u32]);
            dst.extend([b as u32, a as u32]);
            degree[a] += 1;
            degree[b] += 1;
        }
        let inv: Vec<f32> = degree
            .iter()
            .map(|&d| if d > 0 { 1.0 / d as f32 } else { 0.0 })
            .collect();
        let e = src.len();
        Ok(Self {
            num_vertices,
            src: Tensor::from_vec(src, e, device)?,
            dst: Tensor::from_vec(dst, e, device)?,
            inv_degree: Tensor::from_vec(inv, (1, num_vertices, 1), device)?,
        })
    }

    pub fn num_vertices(&self) -> usize {
        self.num_vertices
    }

    /// `mean_{j ∈ N¹(i)} x_j` for `x` of shape `[B, V, C]`: gather the source rows
    /// (`index_select`), sum them into their destinations (`index_add`, whose gradient is
    /// right, unlike `scatter_add`'s for its `init`), scale by the inverse degree.
    pub fn neighbor_mean(&self, x: &Tensor) -> Result<Tensor> {
        let (b, v, c) = x.dims3()?;
        if v != self.num_vertices {
            return Err(Error::Shape {
                what: "graph input",
                expected: format!("[B, {}, C]", self.num_vertices),
                got: format!("{:?}", x.dims()),
            });
        }
        let gathered = x.index_select(&self.src, 1)?;
        let sum = Tensor::zeros((b, v, c), x.dtype(), x.device())?.index_add(&self.dst, &gathered, 1)?;
        Ok(sum.broadcast_mul(&self.inv_degree.to_dtype(x.dtype())?)?)
    }

    /// The inverse degrees as f32, for tests and custom kernels.
    pub fn inverse_degrees(&self) -> Result<Vec<f32>> {
        Ok(self.inv_degree.to_dtype(DType::F32)?.flatten_all()?.to_vec1()?)
    }
}
