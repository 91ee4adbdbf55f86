//! A mesh's 1-ring graph as tensors, built once per mesh: the neighbour mean of Tan et
//! al.'s graph convolution as three large tensor operations, and the Kipf–Welling
//! normalised adjacency of Alt-ConvLSTM's graph convolution as one custom op.

use std::sync::Arc;

use candle_core::{DType, Device, Tensor};
use rayon::prelude::*;
use weft_mesh::{Topology, TriMesh};

use crate::error::{Error, Result};

/// An edge `[a, b]` of a graph over `num_vertices` vertices: two distinct vertices in range.
fn check_edge(num_vertices: usize, a: usize, b: usize) -> Result<()> {
    if a >= num_vertices || b >= num_vertices || a == b {
        return Err(Error::InvalidParameter {
            name: "graph edge",
            value: format!("[{a}, {b}]"),
            reason: "needs two distinct vertices below the vertex count",
        });
    }
    Ok(())
}

/// The directed 1-ring edges of a mesh (`src` → `dst` for every neighbour pair, both ways)
/// and each vertex's inverse degree.
#[derive(Debug, Clone)]
pub struct MeshGraph {
    num_vertices: usize,
    src: Tensor,
    dst: Tensor,
    /// `1/|N¹(i)|` as a `[1, V, 1]` f32 tensor (0 for an isolated vertex).
    inv_degree: Tensor,
    /// The same graph in compressed rows for the fused kernels: row `i`'s neighbours
    /// are `neighbors[offsets[i]..offsets[i + 1]]` (an edge given twice counts twice, as
    /// in the tensors), and `1/|N¹(i)|`.
    offsets: Arc<Vec<usize>>,
    neighbors: Arc<Vec<u32>>,
    inv_degree_values: Arc<Vec<f32>>,
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
            check_edge(num_vertices, a, b)?;
            src.extend([a as u32, b as u32]);
            dst.extend([b as u32, a as u32]);
            degree[a] += 1;
            degree[b] += 1;
        }
        let inv: Vec<f32> = degree
            .iter()
            .map(|&d| if d > 0 { 1.0 / d as f32 } else { 0.0 })
            .collect();
        let mut rows: Vec<Vec<u32>> = vec![Vec::new(); num_vertices];
        for (&s, &d) in src.iter().zip(&dst) {
            rows[d as usize].push(s);
        }
        let mut offsets = Vec::with_capacity(num_vertices + 1);
        offsets.push(0);
        for r in &rows {
            offsets.push(offsets.last().copied().unwrap_or(0) + r.len());
        }
        let neighbors: Vec<u32> = rows.into_iter().flatten().collect();
        let e = src.len();
        Ok(Self {
            num_vertices,
            src: Tensor::from_vec(src, e, device)?,
            dst: Tensor::from_vec(dst, e, device)?,
            inv_degree: Tensor::from_vec(inv.clone(), (1, num_vertices, 1), device)?,
            offsets: Arc::new(offsets),
            neighbors: Arc::new(neighbors),
            inv_degree_values: Arc::new(inv),
        })
    }

    /// Vertex `i`'s neighbours (with multiplicity) and `1/|N¹(i)|`.
    #[inline]
    pub fn neighbors(&self, i: usize) -> (&[u32], f32) {
        (
            &self.neighbors[self.offsets[i]..self.offsets[i + 1]],
            self.inv_degree_values[i],
        )
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

/// Kipf & Welling's normalised adjacency `Â_n = D̂^{−1/2} (A + I) D̂^{−1/2}` of a mesh's
/// 1-ring graph (Alt-ConvLSTM Eq. 9: `Conv(X, Θ) = Â_n X Θ`), built once per mesh and
/// stored in compressed rows.
///
/// [`NormalizedAdjacency::apply`] multiplies a `[..., V, C]` tensor by it as one candle
/// custom op, parallel over rows; the matrix is symmetric, so the backward pass is the
/// same product applied to the incoming gradient. [`NormalizedAdjacency::multiply`] is
/// the same product on plain row-major slices, for a runtime outside candle.
#[derive(Debug, Clone)]
pub struct NormalizedAdjacency {
    /// Row `i` is `columns[offsets[i]..offsets[i + 1]]` (sorted, the diagonal included).
    offsets: Arc<Vec<usize>>,
    columns: Arc<Vec<u32>>,
    values: Arc<Vec<f32>>,
}

impl NormalizedAdjacency {
    /// The normalised adjacency of `mesh`'s edge graph.
    pub fn new(mesh: &TriMesh) -> Result<Self> {
        let topo = Topology::new(mesh);
        Self::from_edges(mesh.num_vertices(), &topo.edges)
    }

    /// The normalised adjacency of undirected `edges` over `num_vertices` vertices
    /// (repeated edges count once).
    pub fn from_edges(num_vertices: usize, edges: &[[usize; 2]]) -> Result<Self> {
        let mut rows: Vec<Vec<u32>> = (0..num_vertices).map(|i| vec![i as u32]).collect();
        for &[a, b] in edges {
            check_edge(num_vertices, a, b)?;
            rows[a].push(b as u32);
            rows[b].push(a as u32);
        }
        for r in &mut rows {
            r.sort_unstable();
            r.dedup();
        }
        // D̂_ii = Σ_j Â_ij: the row's length, self-loop included (never zero).
        let inv_sqrt: Vec<f64> = rows.iter().map(|r| 1.0 / (r.len() as f64).sqrt()).collect();
        let mut offsets = Vec::with_capacity(num_vertices + 1);
        offsets.push(0);
        let mut columns = Vec::new();
        let mut values = Vec::new();
        for (i, r) in rows.iter().enumerate() {
            for &j in r {
                columns.push(j);
                values.push((inv_sqrt[i] * inv_sqrt[j as usize]) as f32);
            }
            offsets.push(columns.len());
        }
        Ok(Self {
            offsets: Arc::new(offsets),
            columns: Arc::new(columns),
            values: Arc::new(values),
        })
    }

    pub fn num_vertices(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Stored entries (self-loops included).
    pub fn num_entries(&self) -> usize {
        self.columns.len()
    }

    /// Row `i`'s columns and values.
    #[inline]
    pub fn row(&self, i: usize) -> (&[u32], &[f32]) {
        let r = self.offsets[i]..self.offsets[i + 1];
        (&self.columns[r.clone()], &self.values[r])
    }

    /// `Â_n x` for `x` of shape `[..., V, C]` (f32), differentiable.
    pub fn apply(&self, x: &Tensor) -> Result<Tensor> {
        let dims = x.dims();
        if dims.len() < 2 || dims[dims.len() - 2] != self.num_vertices() {
            return Err(Error::Shape {
                what: "normalised-adjacency input",
                expected: format!("[..., {}, C]", self.num_vertices()),
                got: format!("{dims:?}"),
            });
        }
        Ok(x.contiguous()?.apply_op1(self.clone())?)
    }

    /// `out = Â_n x` for row-major `[V, channels]` slices (every block of `V` rows of a
    /// longer `x` in turn), rows in parallel.
    pub fn multiply(&self, x: &[f32], channels: usize, out: &mut [f32]) {
        debug_assert_eq!(x.len(), out.len());
        self.product(Columns::whole(x, channels), channels, out, channels, 0, false);
    }

    /// `Â_n x` for one row-major `[V, channels]` slice `x`, written into columns
    /// `offset..offset + channels` of the row-major `[V, stride]` slice `out` (its other
    /// columns untouched), rows in parallel: how a runtime lays several products side by
    /// side as the operand of one matrix product.
    pub fn multiply_into(&self, x: &[f32], channels: usize, out: &mut [f32], stride: usize, offset: usize) {
        debug_assert!(out.len() == self.num_vertices() * stride);
        self.product(Columns::whole(x, channels), channels, out, stride, offset, false);
    }

    /// The general product the kernels use: `Â_n` applied to columns
    /// `x.offset..x.offset + channels` of the row-major `[R, x.stride]` slice `x.data`,
    /// every block of `V` rows in turn (a batch of meshes), written into (or, with
    /// `accumulate`, added onto) columns `offset..offset + channels` of the row-major
    /// `[R, stride]` slice `out`; rows in parallel.
    #[allow(clippy::too_many_arguments)]
    pub fn product(
        &self,
        x: Columns<'_>,
        channels: usize,
        out: &mut [f32],
        stride: usize,
        offset: usize,
        accumulate: bool,
    ) {
        let v = self.num_vertices();
        debug_assert!(offset + channels <= stride && x.offset + channels <= x.stride);
        debug_assert!(out.len().is_multiple_of(v * stride) && x.data.len() / x.stride == out.len() / stride);
        // Blocks of rows per task, each compiled for the CPU's widest vectors (the
        // channel loop is the vector loop).
        out.par_chunks_mut(stride * ROWS_PER_TASK)
            .enumerate()
            .for_each(|(t, rows)| {
                pulp::Arch::new().dispatch(RowProducts {
                    adj: self,
                    first_row: t * ROWS_PER_TASK,
                    x,
                    channels,
                    out: rows,
                    stride,
                    offset,
                    accumulate,
                })
            });
    }
}

/// Columns of a row-major buffer: `data` has rows of `stride` values, the columns start at
/// `offset`.
#[derive(Debug, Clone, Copy)]
pub struct Columns<'a> {
    pub data: &'a [f32],
    pub stride: usize,
    pub offset: usize,
}

impl<'a> Columns<'a> {
    /// Every column of a row-major buffer of `channels` columns.
    pub fn whole(data: &'a [f32], channels: usize) -> Self {
        Self {
            data,
            stride: channels,
            offset: 0,
        }
    }
}

/// Rows per parallel task of [`NormalizedAdjacency::product`].
const ROWS_PER_TASK: usize = 256;

/// Rows `first_row..` of `Â_n x` into `out` (see [`NormalizedAdjacency::product`]).
struct RowProducts<'a> {
    adj: &'a NormalizedAdjacency,
    first_row: usize,
    x: Columns<'a>,
    channels: usize,
    out: &'a mut [f32],
    stride: usize,
    offset: usize,
    accumulate: bool,
}

impl pulp::WithSimd for RowProducts<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let ch = self.channels;
        let v = self.adj.num_vertices();
        let Columns { data, stride, offset } = self.x;
        for (r, row) in self.out.chunks_exact_mut(self.stride).enumerate() {
            let o = &mut row[self.offset..self.offset + ch];
            if !self.accumulate {
                o.fill(0.0);
            }
            let global = self.first_row + r;
            // The block of the batch this row belongs to.
            let base = global - global % v;
            let (cols, vals) = self.adj.row(global % v);
            for (&j, &a) in cols.iter().zip(vals) {
                let start = (base + j as usize) * stride + offset;
                let xj = &data[start..start + ch];
                for (oc, xc) in o.iter_mut().zip(xj) {
                    *oc += a * xc;
                }
            }
        }
    }
}

impl candle_core::CustomOp1 for NormalizedAdjacency {
    fn name(&self) -> &'static str {
        "normalized-adjacency"
    }

    fn cpu_fwd(
        &self,
        s: &candle_core::CpuStorage,
        l: &candle_core::Layout,
    ) -> candle_core::Result<(candle_core::CpuStorage, candle_core::Shape)> {
        let all = s
            .as_slice::<f32>()
            .map_err(|_| candle_core::Error::Msg("normalized-adjacency: expects f32".into()))?;
        let (a, b) = l
            .contiguous_offsets()
            .ok_or_else(|| candle_core::Error::Msg("normalized-adjacency: expects a contiguous input".into()))?;
        let x = &all[a..b];
        let channels = *l.shape().dims().last().unwrap_or(&1);
        let mut out = vec![0.0f32; x.len()];
        self.multiply(x, channels, &mut out);
        Ok((candle_core::CpuStorage::F32(out), l.shape().clone()))
    }

    fn bwd(&self, _arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> candle_core::Result<Option<Tensor>> {
        // Â_n is symmetric: the vector–Jacobian product is the same product.
        Ok(Some(grad_res.contiguous()?.apply_op1(self.clone())?))
    }
}
