//! Tan et al.'s mesh autoencoder ([`crate::embed::MeshAutoencoder`]) as two fused candle
//! custom ops — the encoder and the decoder, each whole — with hand-written backward
//! passes.
//!
//! Through candle's autograd each graph convolution is a gather, a scatter-add, two
//! matrix products and a broadcast per layer, each allocated and walked back separately;
//! on the 4225-vertex sheet the autoencoder's backward pass took about 180 ms of a 250 ms
//! training step (docs/BENCHMARKS.md), for a network of a few MFLOP per frame. Here one
//! graph convolution `C(x)_i = [x_i | mean_{j∈N¹(i)} x_j] · [M; M_N] + b` is one pass over
//! the rows gathering each vertex's 9 channels and its neighbours' mean, then one small
//! product `[512, 18] · [18, 9]` per block of rows (its backward: `[18, 512] · [512, 9]`
//! for the weights, `[512, 9] · [9, 18]` for the operand), and the fully connected layers
//! are single matrix products (faer).
//!
//! Each op takes three arguments: the small parameters flattened (`θ`: the convolutions'
//! `[M; M_N]` and biases and the fully connected layer's bias), the fully connected
//! layer's weight as it is (4.9 M values on the sheet: neither copied into θ nor out of
//! its storage), and the input. Each call's op keeps its forward pass's tape (the layers'
//! operands and pre-activations, a few MB) for its own backward pass.
//!
//! faer's parallel GEMM is not used: its worker threads, which keep spinning after a
//! product, slowed the row passes that follow on a 2-core machine. The small products run
//! on one thread; the fully connected layers' products, memory-bound with a batch of a few
//! frames, are split by output columns over rayon's threads (`gemm_wide`), and the
//! decoder's forward one, `[B, 128] · [128, 9V]`, streams its weight rows through a kernel
//! of its own (`rows_times_wide`).
//!
//! The backward pass of the neighbour mean is its transpose: with `g_i = ∂L/∂mean_i`,
//! `∂L/∂x_j = Σ_{i : j ∈ N¹(i)} g_i / |N¹(i)| = Σ_{i ∈ N¹(j)} g_i / |N¹(i)|` (the 1-ring
//! relation is symmetric).
//!
//! Gradients equal the autograd path's to f32 round-off (tests, every parameter and the
//! input).

use std::sync::{Arc, Mutex};

use candle_core::{CpuStorage, CustomOp3, Layout, Shape, Storage, Tensor};
use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::graph::MeshGraph;
use crate::layers::{GraphConv, LEAKY_SLOPE};
use crate::ops::FEATURE_CHANNELS as C;

/// `[M; M_N]` (`[2C, C]`) and `b` of one graph convolution in θ.
const CONV_PARAMS: usize = 2 * C * C + C;
/// Rows per parallel task.
const ROWS_PER_TASK: usize = 512;

/// The small parameters of `convs` flattened in the kernels' order.
pub(crate) fn conv_parameters(convs: &[GraphConv]) -> Result<Vec<Tensor>> {
    let mut parts = Vec::with_capacity(3 * convs.len());
    for conv in convs {
        let (c_in, c_out) = conv.self_weight.dims2()?;
        if c_in != C || c_out != C {
            return Err(Error::Shape {
                what: "fused graph convolution",
                expected: format!("[{C}, {C}] weights"),
                got: format!("[{c_in}, {c_out}]"),
            });
        }
        parts.push(conv.self_weight.flatten_all()?);
        parts.push(conv.neighbor_weight.flatten_all()?);
        parts.push(conv.bias.flatten_all()?);
    }
    Ok(parts)
}

fn leaky(x: f32) -> f32 {
    if x >= 0.0 { x } else { LEAKY_SLOPE as f32 * x }
}

fn leaky_derivative(x: f32) -> f32 {
    if x >= 0.0 { 1.0 } else { LEAKY_SLOPE as f32 }
}

fn f32_slice<'a>(s: &'a CpuStorage, l: &Layout) -> candle_core::Result<&'a [f32]> {
    let all = s.as_slice::<f32>()?;
    let (a, b) = l
        .contiguous_offsets()
        .ok_or_else(|| candle_core::Error::Msg("fused autoencoder: expects contiguous inputs".into()))?;
    Ok(&all[a..b])
}

/// `f` on the values of a contiguous f32 CPU tensor, borrowed from its storage.
fn with_values<R>(t: &Tensor, f: impl FnOnce(&[f32]) -> R) -> candle_core::Result<R> {
    let (storage, layout) = t.storage_and_layout();
    match &*storage {
        Storage::Cpu(s) => Ok(f(f32_slice(s, layout)?)),
        _ => Err(candle_core::Error::Msg("fused autoencoder: CPU tensors only".into())),
    }
}

/// `out (accum) a · b`, on one thread (see the module's notes).
fn gemm(out: MatMut<'_, f32>, accum: Accum, a: MatRef<'_, f32>, b: MatRef<'_, f32>) {
    faer::linalg::matmul::matmul(out, accum, a, b, 1.0, Par::Seq);
}

/// Output columns below which [`gemm_split`] does not split a product further.
const MIN_SPLIT_COLUMNS: usize = 32;

/// [`gemm`] with the columns of `out` and `b` split in halves, up to `depth` times, the
/// halves multiplied on rayon's threads. The fully connected layers' products stream
/// a 4.9 M-value weight matrix for a few rows of `a`: bound by memory, which two cores
/// stream faster than one. Each piece is still one sequential faer product, so no
/// parallel-GEMM worker is left spinning (the module's notes).
fn gemm_split(out: MatMut<'_, f32>, accum: Accum, a: MatRef<'_, f32>, b: MatRef<'_, f32>, depth: u32) {
    let n = out.ncols();
    if depth == 0 || n < 2 * MIN_SPLIT_COLUMNS {
        return gemm(out, accum, a, b);
    }
    let (o1, o2) = out.split_at_col_mut(n / 2);
    let (b1, b2) = b.split_at_col(n / 2);
    rayon::join(
        || gemm_split(o1, accum, a, b1, depth - 1),
        || gemm_split(o2, accum, a, b2, depth - 1),
    );
}

/// [`gemm_split`] into as many pieces as rayon has threads (a power of two above).
fn gemm_wide(out: MatMut<'_, f32>, accum: Accum, a: MatRef<'_, f32>, b: MatRef<'_, f32>) {
    let depth = rayon::current_num_threads().next_power_of_two().trailing_zeros();
    gemm_split(out, accum, a, b, depth);
}

/// `out += a · w` for a few rows `a` (`[B, k]`, row-major) and a row-major `w` (`[k, n]`)
/// far wider than deep: the decoder's fully connected layer, `[B, 128] · [128, 4225·9]`
/// on the sheet. faer runs this shape as matrix–vector products, the latent roll-out's
/// (`B = 1`) largest single cost in the decoder. Here `w` is
/// streamed once, row by row: each output row takes four scaled `w` rows per pass
/// (four multiply-adds per load and store of the output), the columns split into as many
/// contiguous pieces as rayon has threads.
fn rows_times_wide(out: &mut [f32], a: &[f32], w: &[f32], k: usize, n: usize) {
    if k == 0 || n == 0 {
        // An empty product adds nothing (and `chunks_exact_mut(0)` would panic).
        return;
    }
    let rows = a.len() / k;
    debug_assert_eq!(out.len(), rows * n);
    debug_assert_eq!(w.len(), k * n);
    let threads = rayon::current_num_threads().max(1);
    let piece = n.div_ceil(threads).max(MIN_SPLIT_COLUMNS);
    // Each piece: its column range and every output row's part of it.
    let mut pieces: Vec<(usize, Vec<&mut [f32]>)> = (0..n).step_by(piece).map(|c| (c, Vec::new())).collect();
    for row in out.chunks_exact_mut(n) {
        let mut rest = row;
        for (c, parts) in pieces.iter_mut() {
            let (part, tail) = rest.split_at_mut(piece.min(n - *c));
            parts.push(part);
            rest = tail;
        }
    }
    pieces.into_par_iter().for_each(|(first, parts)| {
        pulp::Arch::new().dispatch(WideRows {
            a,
            w,
            k,
            n,
            first,
            parts,
        });
    });
}

struct WideRows<'a, 'b> {
    a: &'a [f32],
    w: &'a [f32],
    k: usize,
    n: usize,
    /// The piece's first column.
    first: usize,
    /// Each output row's part `[first, first + width)`.
    parts: Vec<&'b mut [f32]>,
}

impl pulp::WithSimd for WideRows<'_, '_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(mut self, simd: S) {
        let Some(width) = self.parts.first().map(|p| p.len()) else {
            return;
        };
        let w_row = |kk: usize| &self.w[kk * self.n + self.first..][..width];
        let mut kk = 0;
        while kk + 4 <= self.k {
            let rows: [_; 4] = std::array::from_fn(|i| S::as_simd_f32s(w_row(kk + i)));
            for (r, out) in self.parts.iter_mut().enumerate() {
                let s: [f32; 4] = std::array::from_fn(|i| self.a[r * self.k + kk + i]);
                let sv = s.map(|x| simd.splat_f32s(x));
                let (head, tail) = S::as_mut_simd_f32s(out);
                for (j, o) in head.iter_mut().enumerate() {
                    let mut acc = simd.mul_add_f32s(sv[0], rows[0].0[j], *o);
                    acc = simd.mul_add_f32s(sv[1], rows[1].0[j], acc);
                    acc = simd.mul_add_f32s(sv[2], rows[2].0[j], acc);
                    *o = simd.mul_add_f32s(sv[3], rows[3].0[j], acc);
                }
                for (j, o) in tail.iter_mut().enumerate() {
                    *o += s[0] * rows[0].1[j] + s[1] * rows[1].1[j] + s[2] * rows[2].1[j] + s[3] * rows[3].1[j];
                }
            }
            kk += 4;
        }
        for kk in kk..self.k {
            let (head_w, tail_w) = S::as_simd_f32s(w_row(kk));
            for (r, out) in self.parts.iter_mut().enumerate() {
                let s = self.a[r * self.k + kk];
                let sv = simd.splat_f32s(s);
                let (head, tail) = S::as_mut_simd_f32s(out);
                for (o, x) in head.iter_mut().zip(head_w) {
                    *o = simd.mul_add_f32s(sv, *x, *o);
                }
                for (o, x) in tail.iter_mut().zip(tail_w) {
                    *o += s * x;
                }
            }
        }
    }
}

/// `out = aᵀ c` for row-major `a` `[B, m]` and `c` `[B, n]` with few rows `B` (a weight
/// gradient summed over a batch): each output row a sum of `B` scaled rows of `c`,
/// vectorised along the row and parallel over rows. A general product with an inner
/// dimension of 8 ran at a tenth of this speed.
fn outer_sum(a: &[f32], c: &[f32], m: usize, n: usize, out: &mut [f32]) {
    let b = a.len() / m;
    out.par_chunks_mut(n * 64).enumerate().for_each(|(task, rows)| {
        pulp::Arch::new().dispatch(OuterRows {
            a,
            c,
            m,
            n,
            b,
            first: task * 64,
            rows,
        })
    });
}

struct OuterRows<'a> {
    a: &'a [f32],
    c: &'a [f32],
    m: usize,
    n: usize,
    b: usize,
    first: usize,
    rows: &'a mut [f32],
}

impl pulp::WithSimd for OuterRows<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        for (r, out) in self.rows.chunks_exact_mut(self.n).enumerate() {
            let i = self.first + r;
            out.fill(0.0);
            for k in 0..self.b {
                let s = self.a[k * self.m + i];
                for (o, x) in out.iter_mut().zip(&self.c[k * self.n..(k + 1) * self.n]) {
                    *o += s * x;
                }
            }
        }
    }
}

/// `tanh` of every value (the vectorised approximation of [`crate::fast`], within 4e-7).
fn tanh_all(x: &[f32]) -> Vec<f32> {
    let mut y = x.to_vec();
    y.par_chunks_mut(1 << 14).for_each(crate::fast::tanh_in_place);
    y
}

fn view(data: &[f32], rows: usize, cols: usize) -> MatRef<'_, f32> {
    MatRef::from_row_major_slice(data, rows, cols)
}

fn view_mut(data: &mut [f32], rows: usize, cols: usize) -> MatMut<'_, f32> {
    MatMut::from_row_major_slice_mut(data, rows, cols)
}

/// One graph convolution on the rows of `h` (`[R, C]`, blocks of `V` rows): writes the
/// operand `a = [h | mean h]` (`[R, 2C]`) and the pre-activation `a · W + b` (`[R, C]`).
///
/// Each task gathers its rows' operands, then multiplies them by `W` as one small
/// matrix product (`[512, 18] · [18, 9]`, faer's vectorised kernels): a row at a time,
/// the 18 × 9 product ran as scalar code (nine channels do not fill an 8-lane vector
/// evenly) and was most of the forward pass.
fn conv_forward(graph: &MeshGraph, theta: &[f32], h: &[f32], a: &mut [f32], pre: &mut [f32]) {
    let (w, b) = theta.split_at(2 * C * C);
    let v = graph.num_vertices();
    a.par_chunks_mut(2 * C * ROWS_PER_TASK)
        .zip(pre.par_chunks_mut(C * ROWS_PER_TASK))
        .enumerate()
        .for_each(|(task, (a, pre))| {
            let first = task * ROWS_PER_TASK;
            for (r, ar) in a.chunks_exact_mut(2 * C).enumerate() {
                let row = first + r;
                let base = row - row % v;
                let (nb, inv) = graph.neighbors(row % v);
                let (own, mean) = ar.split_at_mut(C);
                own.copy_from_slice(&h[row * C..(row + 1) * C]);
                mean.fill(0.0);
                for &j in nb {
                    let hj = &h[(base + j as usize) * C..][..C];
                    for (m, x) in mean.iter_mut().zip(hj) {
                        *m += x;
                    }
                }
                mean.iter_mut().for_each(|m| *m *= inv);
            }
            for pr in pre.chunks_exact_mut(C) {
                pr.copy_from_slice(b);
            }
            let rows = pre.len() / C;
            gemm(
                view_mut(pre, rows, C),
                Accum::Add,
                view(a, rows, 2 * C),
                view(w, 2 * C, C),
            );
        });
}

/// The backward pass of [`conv_forward`] from `dpre` (`[R, C]`): `∂L/∂[M; M_N]` and
/// `∂L/∂b` into `d_theta` (`CONV_PARAMS` values, accumulated in f64 over the rows), and
/// `∂L/∂h` into `dh` when asked for.
fn conv_backward(
    graph: &MeshGraph,
    theta: &[f32],
    a: &[f32],
    dpre: &[f32],
    d_theta: &mut [f32],
    dh: Option<&mut [f32]>,
) {
    let v = graph.num_vertices();
    let w = &theta[..2 * C * C];
    // Per task `aᵀ · ∂L/∂pre` as one small product (f32 over its 512 rows), summed over
    // the tasks in f64.
    let sums = a
        .par_chunks(2 * C * ROWS_PER_TASK)
        .zip(dpre.par_chunks(C * ROWS_PER_TASK))
        .map(|(a, dp)| {
            let rows = dp.len() / C;
            let mut sw = vec![0.0f32; 2 * C * C];
            gemm(
                view_mut(&mut sw, 2 * C, C),
                Accum::Replace,
                view(a, rows, 2 * C).transpose(),
                view(dp, rows, C),
            );
            let mut s: Vec<f64> = sw.iter().map(|&x| f64::from(x)).collect();
            s.resize(CONV_PARAMS, 0.0);
            for dr in dp.chunks_exact(C) {
                for (acc, g) in s[2 * C * C..].iter_mut().zip(dr) {
                    *acc += f64::from(*g);
                }
            }
            s
        })
        .reduce(
            || vec![0.0f64; CONV_PARAMS],
            |mut x, y| {
                x.iter_mut().zip(y).for_each(|(a, b)| *a += b);
                x
            },
        );
    for (d, s) in d_theta.iter_mut().zip(sums) {
        *d = s as f32;
    }
    let Some(dh) = dh else { return };
    // ∂L/∂a = ∂L/∂pre · Wᵀ; the mean's half scaled by 1/|N¹(i)| of its own row.
    let rows = dpre.len() / C;
    let mut da = vec![0.0f32; rows * 2 * C];
    da.par_chunks_mut(2 * C * ROWS_PER_TASK)
        .zip(dpre.par_chunks(C * ROWS_PER_TASK))
        .enumerate()
        .for_each(|(task, (da, dp))| {
            let n = dp.len() / C;
            gemm(
                view_mut(da, n, 2 * C),
                Accum::Replace,
                view(dp, n, C),
                view(w, 2 * C, C).transpose(),
            );
            for (r, dar) in da.chunks_exact_mut(2 * C).enumerate() {
                let row = task * ROWS_PER_TASK + r;
                let (_, inv) = graph.neighbors(row % v);
                dar[C..].iter_mut().for_each(|x| *x *= inv);
            }
        });
    dh.par_chunks_mut(C * ROWS_PER_TASK).enumerate().for_each(|(task, dh)| {
        for (r, dhr) in dh.chunks_exact_mut(C).enumerate() {
            let row = task * ROWS_PER_TASK + r;
            let base = row - row % v;
            dhr.copy_from_slice(&da[row * 2 * C..row * 2 * C + C]);
            for &i in graph.neighbors(row % v).0 {
                let g = &da[(base + i as usize) * 2 * C + C..][..C];
                for (x, y) in dhr.iter_mut().zip(g) {
                    *x += y;
                }
            }
        }
    });
}

/// The taped forward pass of a stack of convolutions from `h0` (`[R, C]`): each layer's
/// operand, pre-activation and output.
struct ConvTape {
    a: Vec<Vec<f32>>,
    pre: Vec<Vec<f32>>,
    out: Vec<Vec<f32>>,
}

/// Convolutions `theta` (`CONV_PARAMS` each) on `h0`; every activation is the leaky ReLU
/// but the last one's, `tanh` where `tanh_last`.
fn convs_forward(graph: &MeshGraph, theta: &[f32], h0: &[f32], tanh_last: bool) -> ConvTape {
    let layers = theta.len() / CONV_PARAMS;
    let rows = h0.len() / C;
    let mut tape = ConvTape {
        a: Vec::with_capacity(layers),
        pre: Vec::with_capacity(layers),
        out: Vec::with_capacity(layers),
    };
    for l in 0..layers {
        let h = if l == 0 { h0 } else { &tape.out[l - 1] };
        let mut a = vec![0.0f32; rows * 2 * C];
        let mut pre = vec![0.0f32; rows * C];
        conv_forward(
            graph,
            &theta[l * CONV_PARAMS..(l + 1) * CONV_PARAMS],
            h,
            &mut a,
            &mut pre,
        );
        let out: Vec<f32> = if tanh_last && l == layers - 1 {
            tanh_all(&pre)
        } else {
            pre.par_iter().map(|&x| leaky(x)).collect()
        };
        tape.a.push(a);
        tape.pre.push(pre);
        tape.out.push(out);
    }
    tape
}

/// The backward pass of [`convs_forward`] from `∂L/∂out` of the last layer, for the tape's
/// rows `rows` (whole frames: `d_out` holds those rows only); returns `∂L/∂h0` of those
/// rows and writes the convolutions' parameter gradients into `d_theta`.
fn convs_backward(
    graph: &MeshGraph,
    theta: &[f32],
    tape: &ConvTape,
    rows: std::ops::Range<usize>,
    d_out: Vec<f32>,
    tanh_last: bool,
    d_theta: &mut [f32],
) -> Vec<f32> {
    let layers = theta.len() / CONV_PARAMS;
    let part = |width: usize| rows.start * width..rows.end * width;
    let mut d = d_out;
    for l in (0..layers).rev() {
        let (out, pre, a) = (&tape.out[l], &tape.pre[l], &tape.a[l]);
        let dpre: Vec<f32> = if tanh_last && l == layers - 1 {
            d.par_iter()
                .zip(&out[part(C)])
                .map(|(g, y)| g * (1.0 - y * y))
                .collect()
        } else {
            d.par_iter()
                .zip(&pre[part(C)])
                .map(|(g, x)| g * leaky_derivative(*x))
                .collect()
        };
        let mut dh = vec![0.0f32; dpre.len()];
        conv_backward(
            graph,
            &theta[l * CONV_PARAMS..(l + 1) * CONV_PARAMS],
            &a[part(2 * C)],
            &dpre,
            &mut d_theta[l * CONV_PARAMS..(l + 1) * CONV_PARAMS],
            Some(&mut dh),
        );
        d = dh;
    }
    d
}

/// The frames `[B, width]` of `grad` from the first to the last one with a nonzero value.
/// A frame outside them adds nothing to any gradient, so the backward passes skip it: the
/// embedding's loss sends the two predecessor frames of each window through the networks
/// in the same batch as the window's frame, and only the window's frame carries gradient
/// (Tan et al. Eq. 9–10 detach the predecessors).
fn frames_with_gradient(grad: &[f32], width: usize) -> std::ops::Range<usize> {
    let nonzero = |f: &[f32]| f.iter().any(|&g| g != 0.0);
    let mut frames = grad.chunks_exact(width);
    let first = frames.position(nonzero).unwrap_or(grad.len() / width);
    let last = grad.chunks_exact(width).rposition(nonzero).map_or(first, |l| l + 1);
    first..last
}

/// Column sums of a row-major `[rows, cols]` buffer, in f64.
fn column_sums(x: &[f32], cols: usize) -> Vec<f32> {
    let mut s = vec![0.0f64; cols];
    for row in x.chunks_exact(cols) {
        for (a, b) in s.iter_mut().zip(row) {
            *a += f64::from(*b);
        }
    }
    s.into_iter().map(|v| v as f32).collect()
}

/// The encoder `E = F ∘ C_L ∘ … ∘ C_1`: (θ = convolutions then the fully connected
/// bias, `W_F` `[V·C, latent]`, features `[B, V, C]`) → codes `[B, latent]`.
pub(crate) struct EncoderOp {
    graph: Arc<MeshGraph>,
    latent: usize,
    tape: Mutex<Option<ConvTape>>,
}

impl EncoderOp {
    pub fn new(graph: Arc<MeshGraph>, latent: usize) -> Self {
        Self {
            graph,
            latent,
            tape: Mutex::new(None),
        }
    }

    fn forward(&self, theta: &[f32], w_fc: &[f32], x: &[f32]) -> (ConvTape, Vec<f32>) {
        let conv_len = theta.len() - self.latent;
        let tape = convs_forward(&self.graph, &theta[..conv_len], x, false);
        let h: &[f32] = tape.out.last().map_or(x, |o| o.as_slice());
        let width = self.graph.num_vertices() * C;
        let b = x.len() / width;
        let mut z: Vec<f32> = (0..b).flat_map(|_| theta[conv_len..].iter().copied()).collect();
        gemm_wide(
            view_mut(&mut z, b, self.latent),
            Accum::Add,
            view(h, b, width),
            view(w_fc, width, self.latent),
        );
        (tape, z)
    }
}

impl CustomOp3 for EncoderOp {
    fn name(&self) -> &'static str {
        "fused-mesh-encoder"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (theta, w_fc, x) = (f32_slice(s1, l1)?, f32_slice(s2, l2)?, f32_slice(s3, l3)?);
        let b = l3.shape().dims()[0];
        let (tape, z) = self.forward(theta, w_fc, x);
        if let Ok(mut slot) = self.tape.lock() {
            *slot = Some(tape);
        }
        Ok((CpuStorage::F32(z), Shape::from((b, self.latent))))
    }

    fn bwd(
        &self,
        theta_t: &Tensor,
        w_fc_t: &Tensor,
        x_t: &Tensor,
        _res: &Tensor,
        grad_res: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let theta: Vec<f32> = theta_t.flatten_all()?.to_vec1()?;
        let x: Vec<f32> = x_t.flatten_all()?.to_vec1()?;
        let dz: Vec<f32> = grad_res.flatten_all()?.to_vec1()?;
        let taped = self.tape.lock().ok().and_then(|mut slot| slot.take());
        let tape = match taped {
            Some(t) => t,
            None => with_values(w_fc_t, |w_fc| self.forward(&theta, w_fc, &x).0)?,
        };
        let conv_len = theta.len() - self.latent;
        let v = self.graph.num_vertices();
        let width = v * C;
        let b = x.len() / width;
        let h: &[f32] = tape.out.last().map_or(&x, |o| o.as_slice());
        let mut d_theta = vec![0.0f32; theta.len()];
        d_theta[conv_len..].copy_from_slice(&column_sums(&dz, self.latent));
        // Frames without gradient are skipped (`frames_with_gradient`).
        let frames = frames_with_gradient(&dz, self.latent);
        let (h, dz) = (
            &h[frames.start * width..frames.end * width],
            &dz[frames.start * self.latent..frames.end * self.latent],
        );
        let mut d_w = vec![0.0f32; width * self.latent];
        outer_sum(h, dz, width, self.latent, &mut d_w);
        let mut dh = vec![0.0f32; frames.len() * width];
        with_values(w_fc_t, |w_fc| {
            gemm_wide(
                view_mut(&mut dh, frames.len(), width),
                Accum::Replace,
                view(dz, frames.len(), self.latent),
                view(w_fc, width, self.latent).transpose(),
            )
        })?;
        let dx_frames = convs_backward(
            &self.graph,
            &theta[..conv_len],
            &tape,
            frames.start * v..frames.end * v,
            dh,
            false,
            &mut d_theta[..conv_len],
        );
        let mut dx = vec![0.0f32; b * width];
        dx[frames.start * width..frames.end * width].copy_from_slice(&dx_frames);
        let dev = theta_t.device();
        Ok((
            Some(Tensor::from_vec(d_theta, theta_t.shape(), dev)?),
            Some(Tensor::from_vec(d_w, w_fc_t.shape(), dev)?),
            Some(Tensor::from_vec(dx, x_t.shape(), dev)?),
        ))
    }
}

/// The decoder `D = C_Lᵀ ∘ … ∘ C_1ᵀ ∘ Fᵀ`: (θ = the fully connected bias `[V·C]` then
/// the convolutions, `W_F` `[latent, V·C]`, codes `[B, latent]`) → normalised features
/// `[B, V, C]`, the last convolution ending in `tanh`.
pub(crate) struct DecoderOp {
    graph: Arc<MeshGraph>,
    latent: usize,
    tape: Mutex<Option<(Vec<f32>, ConvTape)>>,
}

impl DecoderOp {
    pub fn new(graph: Arc<MeshGraph>, latent: usize) -> Self {
        Self {
            graph,
            latent,
            tape: Mutex::new(None),
        }
    }

    /// The fully connected layer's pre-activation and the convolutions' tape.
    fn forward(&self, theta: &[f32], w_fc: &[f32], z: &[f32]) -> (Vec<f32>, Vec<f32>, ConvTape) {
        let width = self.graph.num_vertices() * C;
        let b = z.len() / self.latent;
        let mut u_pre: Vec<f32> = (0..b).flat_map(|_| theta[..width].iter().copied()).collect();
        rows_times_wide(&mut u_pre, z, w_fc, self.latent, width);
        let u: Vec<f32> = u_pre.par_iter().map(|&x| leaky(x)).collect();
        let tape = convs_forward(&self.graph, &theta[width..], &u, true);
        (u_pre, u, tape)
    }
}

impl CustomOp3 for DecoderOp {
    fn name(&self) -> &'static str {
        "fused-mesh-decoder"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (theta, w_fc, z) = (f32_slice(s1, l1)?, f32_slice(s2, l2)?, f32_slice(s3, l3)?);
        let b = l3.shape().dims()[0];
        let (u_pre, u, tape) = self.forward(theta, w_fc, z);
        let y = tape.out.last().cloned().unwrap_or(u);
        if let Ok(mut slot) = self.tape.lock() {
            *slot = Some((u_pre, tape));
        }
        Ok((CpuStorage::F32(y), Shape::from((b, self.graph.num_vertices(), C))))
    }

    fn bwd(
        &self,
        theta_t: &Tensor,
        w_fc_t: &Tensor,
        z_t: &Tensor,
        _res: &Tensor,
        grad_res: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let theta: Vec<f32> = theta_t.flatten_all()?.to_vec1()?;
        let z: Vec<f32> = z_t.flatten_all()?.to_vec1()?;
        let dy: Vec<f32> = grad_res.flatten_all()?.to_vec1()?;
        let taped = self.tape.lock().ok().and_then(|mut slot| slot.take());
        let (u_pre, tape) = match taped {
            Some(t) => t,
            None => with_values(w_fc_t, |w_fc| {
                let (u_pre, _, tape) = self.forward(&theta, w_fc, &z);
                (u_pre, tape)
            })?,
        };
        let v = self.graph.num_vertices();
        let width = v * C;
        let b = z.len() / self.latent;
        let mut d_theta = vec![0.0f32; theta.len()];
        // Frames without gradient are skipped (`frames_with_gradient`).
        let frames = frames_with_gradient(&dy, width);
        let dy = dy[frames.start * width..frames.end * width].to_vec();
        let du = convs_backward(
            &self.graph,
            &theta[width..],
            &tape,
            frames.start * v..frames.end * v,
            dy,
            true,
            &mut d_theta[width..],
        );
        let du_pre: Vec<f32> = du
            .par_iter()
            .zip(&u_pre[frames.start * width..frames.end * width])
            .map(|(g, x)| g * leaky_derivative(*x))
            .collect();
        d_theta[..width].copy_from_slice(&column_sums(&du_pre, width));
        let mut d_w = vec![0.0f32; self.latent * width];
        let z_frames = &z[frames.start * self.latent..frames.end * self.latent];
        outer_sum(z_frames, &du_pre, self.latent, width, &mut d_w);
        let mut dz = vec![0.0f32; b * self.latent];
        with_values(w_fc_t, |w_fc| {
            gemm_wide(
                view_mut(
                    &mut dz[frames.start * self.latent..frames.end * self.latent],
                    frames.len(),
                    self.latent,
                ),
                Accum::Replace,
                view(&du_pre, frames.len(), width),
                view(w_fc, self.latent, width).transpose(),
            )
        })?;
        let dev = theta_t.device();
        Ok((
            Some(Tensor::from_vec(d_theta, theta_t.shape(), dev)?),
            Some(Tensor::from_vec(d_w, w_fc_t.shape(), dev)?),
            Some(Tensor::from_vec(dz, z_t.shape(), dev)?),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wide_row_product_equals_faers_product() {
        // Depths with and without a remainder after the passes of four `w` rows, widths
        // below the split minimum, uneven pieces and a vector tail, one to eight rows.
        let mut state = 11u32;
        let mut next = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        for (rows, inner, cols) in [(1, 128, 1001), (3, 37, 131), (8, 9, 63), (2, 6, 20), (5, 3, 517)] {
            let a: Vec<f32> = (0..rows * inner).map(|_| next()).collect();
            let w: Vec<f32> = (0..inner * cols).map(|_| next()).collect();
            let start: Vec<f32> = (0..rows * cols).map(|_| next()).collect();
            let (mut reference, mut wide) = (start.clone(), start.clone());
            gemm(
                view_mut(&mut reference, rows, cols),
                Accum::Add,
                view(&a, rows, inner),
                view(&w, inner, cols),
            );
            rows_times_wide(&mut wide, &a, &w, inner, cols);
            for (i, (x, y)) in reference.iter().zip(&wide).enumerate() {
                assert!(
                    (x - y).abs() <= 1e-5 * (1.0 + x.abs()),
                    "[{rows}, {inner}] · [{inner}, {cols}]: entry {i}: {y} against {x}"
                );
            }
            assert_ne!(wide, start, "[{rows}, {inner}] · [{inner}, {cols}] added nothing");
        }
        // Empty depth or width: nothing to add, no panic.
        let mut out = vec![1.5f32; 3];
        rows_times_wide(&mut out, &[], &[], 0, 1);
        rows_times_wide(&mut out[..0], &[2.0; 3], &[], 1, 0);
        assert_eq!(out, vec![1.5; 3]);
    }

    #[test]
    fn a_product_split_by_columns_equals_the_whole_product() {
        // Odd column counts (uneven halves), splits down to the minimum width, `b` both
        // row-major and transposed (the layers' forward and backward products), and both
        // accumulation modes.
        let mut state = 7u32;
        let mut next = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        for (rows, inner, cols, depth) in [(3, 37, 131, 3), (2, 300, 70, 1), (1, 128, 1001, 4), (4, 9, 63, 2)] {
            let a: Vec<f32> = (0..rows * inner).map(|_| next()).collect();
            let b: Vec<f32> = (0..inner * cols).map(|_| next()).collect();
            let bt: Vec<f32> = (0..inner * cols).map(|_| next()).collect();
            let start: Vec<f32> = (0..rows * cols).map(|_| next()).collect();
            for (transposed, accum) in [(false, Accum::Add), (true, Accum::Replace)] {
                let rhs = |data| {
                    if transposed {
                        view(data, cols, inner).transpose()
                    } else {
                        view(data, inner, cols)
                    }
                };
                let source = if transposed { &bt } else { &b };
                let (mut whole, mut split) = (start.clone(), start.clone());
                gemm(
                    view_mut(&mut whole, rows, cols),
                    accum,
                    view(&a, rows, inner),
                    rhs(source),
                );
                gemm_split(
                    view_mut(&mut split, rows, cols),
                    accum,
                    view(&a, rows, inner),
                    rhs(source),
                    depth,
                );
                let scale = whole.iter().fold(0.0f32, |m, x| m.max(x.abs()));
                let gap = whole.iter().zip(&split).fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
                assert!(
                    gap <= 1e-6 * scale,
                    "{rows}×{inner}·{inner}×{cols} depth {depth}: gap {gap}"
                );
            }
        }
    }
}
