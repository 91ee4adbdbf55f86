//! One statement of the graph ConvLSTM cells' elementwise equations over f32 rows, for the
//! two paths outside candle's autograd: the fused training op ([`super::fused`]) and the
//! roll-out runtime ([`super::runtime`]). The autograd path ([`super::model`]) writes the
//! same equations in tensor operations; both paths are tested against it to round-off.
//!
//! What is here, and only here: the gate layout of a row, the nonlinearities and state
//! updates of Eq. 5 (forward, and their derivatives for the fused backward pass), the
//! network's input row and its readout (Eq. 11 and the baselines'). What is not: the
//! graph convolutions and the gate products (matrix products over all rows, which each
//! path lays out for its own buffers), and the tape.
//!
//! **Gate layout.** The gates of one vertex row are `4c` numbers, `[i | f | c̃ | o]`, in
//! the column order of the stacked weights `W_x`, `W_h` (`[c_in, 4c]`, `[c, 4c]`) and the
//! bias `[4c]`; the input and forget gates' peepholes `W_if` (`[c, 2c]`) add onto the
//! first `2c` columns, the output gate's `W_o` (`[c, c]`) onto the last `c`. The passes
//! activate the gates in place (the fused backward pass reads them from its tape).

use rayon::prelude::*;

use super::model::{INPUT_CHANNELS, Variant};
use crate::fast::{sigmoid_f32, tanh_f32};

/// What a cell's peepholes look at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Peephole {
    /// Alt-ConvLSTM: the accumulation `Y`.
    Accumulation,
    /// Vanilla ConvLSTM-CP: the cell state `C`.
    Cell,
    /// Vanilla ConvLSTM-NP.
    None,
}

/// Gates per channel: i, f, c̃, o.
pub(super) const GATES: usize = 4;

/// Eq. 5, lines 1–4, over all rows, `block` rows per parallel task: see [`cell_forward_rows`].
#[allow(clippy::too_many_arguments)]
pub(super) fn cell_forward(
    block: usize,
    c: usize,
    gates: &mut [f32],
    cell: &mut [f32],
    cell_prev: &[f32],
    y: Option<&mut [f32]>,
    skip: Option<&[f32]>,
    unit: f32,
) {
    let n = block * c;
    let g_chunks: Vec<&mut [f32]> = gates.chunks_mut(GATES * n).collect();
    let count = g_chunks.len();
    let c_chunks: Vec<&mut [f32]> = cell.chunks_mut(n).collect();
    let y_chunks: Vec<Option<&mut [f32]>> = match y {
        Some(y) => y.chunks_mut(n).map(Some).collect(),
        None => (0..count).map(|_| None).collect(),
    };
    (g_chunks, c_chunks, y_chunks)
        .into_par_iter()
        .enumerate()
        .for_each(|(task, (gates, cell, y))| {
            let r = task * n..task * n + cell.len();
            pulp::Arch::new().dispatch(CellUpdate {
                c,
                gates,
                cell,
                cell_prev: &cell_prev[r.clone()],
                y,
                skip: skip.map(|s| &s[r]),
                unit,
            })
        });
}

/// Eq. 5, lines 5–6, over all rows: see [`hidden_forward_rows`].
pub(super) fn hidden_forward(block: usize, c: usize, gates: &mut [f32], cell: &[f32], h: &mut [f32]) {
    let n = block * c;
    gates
        .par_chunks_mut(GATES * n)
        .zip(cell.par_chunks(n))
        .zip(h.par_chunks_mut(n))
        .for_each(|((gates, cell), h)| pulp::Arch::new().dispatch(HiddenUpdate { c, gates, cell, h }));
}

/// The backward pass through line 6 over all rows: see [`hidden_backward_rows`].
pub(super) fn hidden_backward(block: usize, c: usize, gates: &mut [f32], cell: &[f32], dh: &[f32], dc: &mut [f32]) {
    let n = block * c;
    gates
        .par_chunks_mut(GATES * n)
        .zip(cell.par_chunks(n))
        .zip(dh.par_chunks(n))
        .zip(dc.par_chunks_mut(n))
        .for_each(|(((gates, cell), dh), dc)| pulp::Arch::new().dispatch(HiddenBackward { c, gates, cell, dh, dc }));
}

/// The backward pass through lines 1–4 over all rows: see [`cell_backward_rows`].
pub(super) fn cell_backward(
    block: usize,
    c: usize,
    gates: &mut [f32],
    cell_prev: &[f32],
    dc: &mut [f32],
    dy: Option<&[f32]>,
    unit: f32,
) {
    let n = block * c;
    gates
        .par_chunks_mut(GATES * n)
        .zip(cell_prev.par_chunks(n))
        .zip(dc.par_chunks_mut(n))
        .enumerate()
        .for_each(|(task, ((gates, cell_prev), dc))| {
            let dy = dy.map(|d| &d[task * n..task * n + dc.len()]);
            pulp::Arch::new().dispatch(CellBackward {
                c,
                gates,
                cell_prev,
                dc,
                dy,
                unit,
            })
        });
}

/// The first cell's input rows `[X_t, X_t − X_{t−1}, Y₀ − X₀]` (§4.3), standardised as the
/// network was trained ([`super::Scaling`]): `(x − mean) · inv_std` per channel. `xt`,
/// `dx` and `offset0` are `[R, 3]`, `input` `[R, 9]`.
pub(super) fn standardized_input(
    xt: &[f32],
    dx: &[f32],
    offset0: &[f32],
    mean: &[f32; INPUT_CHANNELS],
    inv_std: &[f32; INPUT_CHANNELS],
    input: &mut [f32],
) {
    for (r, row) in input.chunks_exact_mut(INPUT_CHANNELS).enumerate() {
        let v = 3 * r..3 * r + 3;
        row[..3].copy_from_slice(&xt[v.clone()]);
        row[3..6].copy_from_slice(&dx[v.clone()]);
        row[6..].copy_from_slice(&offset0[v]);
        for ((x, m), s) in row.iter_mut().zip(mean).zip(inv_std) {
            *x = (*x - m) * s;
        }
    }
}

/// The predicted surface `Ŷ_t` from the output cell: its accumulation `y` (Alt-ConvLSTM,
/// Eq. 11), the pose plus the offset state `X_t + unit · C_t` (the `-Y` baselines), or
/// the previous prediction moved by the velocity state and the pose's motion
/// `Ŷ_{t−1} + unit · C_t + (X_t − X_{t−1})` (the `-ΔY` baselines).
pub(super) fn readout(
    variant: Variant,
    y: Option<&[f32]>,
    c_out: &[f32],
    xt: &[f32],
    previous: &[f32],
    dx: &[f32],
    unit: f32,
) -> Vec<f32> {
    match variant {
        Variant::Alt => y.unwrap_or_else(|| unreachable!("Alt-ConvLSTM accumulates")).to_vec(),
        v if v.outputs_position() => xt.iter().zip(c_out).map(|(x, c)| x + unit * c).collect(),
        _ => (0..c_out.len())
            .map(|d| previous[d] + unit * c_out[d] + dx[d])
            .collect(),
    }
}

/// Eq. 5, lines 1–4, on a block of rows: activates i, f and c̃ in place, writes
/// `C_t = f∘C_{t−1} + i∘c̃` and adds `unit · C_t + skip` onto the accumulation.
#[inline(always)]
fn cell_forward_rows(
    c: usize,
    gates: &mut [f32],
    cell: &mut [f32],
    cell_prev: &[f32],
    y: Option<&mut [f32]>,
    skip: Option<&[f32]>,
    unit: f32,
) {
    for ((g, ct), cp) in gates
        .chunks_exact_mut(GATES * c)
        .zip(cell.chunks_exact_mut(c))
        .zip(cell_prev.chunks_exact(c))
    {
        let (i, rest) = g.split_at_mut(c);
        let (f, rest) = rest.split_at_mut(c);
        let candidate = &mut rest[..c];
        for ((((ck, ik), fk), gk), pk) in ct.iter_mut().zip(i).zip(f).zip(candidate).zip(cp) {
            *ik = sigmoid_f32(*ik);
            *fk = sigmoid_f32(*fk);
            *gk = tanh_f32(*gk);
            *ck = *fk * pk + *ik * *gk;
        }
    }
    if let Some(y) = y {
        for (yk, ck) in y.iter_mut().zip(cell.iter()) {
            *yk += unit * ck;
        }
        if let Some(skip) = skip {
            for (yk, sk) in y.iter_mut().zip(skip) {
                *yk += sk;
            }
        }
    }
}

/// Eq. 5, lines 5–6: activates o in place and writes `H_t = o∘tanh(C_t)`.
#[inline(always)]
fn hidden_forward_rows(c: usize, gates: &mut [f32], cell: &[f32], h: &mut [f32]) {
    for ((g, ct), hr) in gates
        .chunks_exact_mut(GATES * c)
        .zip(cell.chunks_exact(c))
        .zip(h.chunks_exact_mut(c))
    {
        for ((hk, ok), ck) in hr.iter_mut().zip(&mut g[3 * c..]).zip(ct) {
            *ok = sigmoid_f32(*ok);
            *hk = *ok * tanh_f32(*ck);
        }
    }
}

/// The backward pass through line 6: `∂L/∂o_pre = ∂L/∂H ∘ tanh C ∘ o(1 − o)` into the o
/// slot, and `∂L/∂C += ∂L/∂H ∘ o ∘ (1 − tanh² C)`.
#[inline(always)]
fn hidden_backward_rows(c: usize, gates: &mut [f32], cell: &[f32], dh: &[f32], dc: &mut [f32]) {
    for (((g, ct), dhr), dcr) in gates
        .chunks_exact_mut(GATES * c)
        .zip(cell.chunks_exact(c))
        .zip(dh.chunks_exact(c))
        .zip(dc.chunks_exact_mut(c))
    {
        for (((ok, ck), dhk), dck) in g[3 * c..].iter_mut().zip(ct).zip(dhr).zip(dcr) {
            let o = *ok;
            let tc = tanh_f32(*ck);
            *ok = dhk * tc * o * (1.0 - o);
            *dck += dhk * o * (1.0 - tc * tc);
        }
    }
}

/// The backward pass through lines 1–4 (after `∂L/∂C_t` is complete but for the
/// accumulation's `unit · ∂L/∂Y_t`, added here): the pre-activation gradients of i, f and
/// c̃ into their slots, and `∂L/∂C_t` replaced by its share of `∂L/∂C_{t−1}`, `∘ f`.
#[inline(always)]
fn cell_backward_rows(c: usize, gates: &mut [f32], cell_prev: &[f32], dc: &mut [f32], dy: Option<&[f32]>, unit: f32) {
    for (r, ((g, cp), dcr)) in gates
        .chunks_exact_mut(GATES * c)
        .zip(cell_prev.chunks_exact(c))
        .zip(dc.chunks_exact_mut(c))
        .enumerate()
    {
        let dyr = dy.map(|d| &d[r * c..(r + 1) * c]);
        let (i, rest) = g.split_at_mut(c);
        let (f, rest) = rest.split_at_mut(c);
        let candidate = &mut rest[..c];
        for (k, ((((ik, fk), gk), pk), dck)) in i.iter_mut().zip(f).zip(candidate).zip(cp).zip(dcr).enumerate() {
            let d = *dck + dyr.map_or(0.0, |y| unit * y[k]);
            let (iv, fv, gv) = (*ik, *fk, *gk);
            *ik = d * gv * iv * (1.0 - iv);
            *fk = d * pk * fv * (1.0 - fv);
            *gk = d * iv * (1.0 - gv * gv);
            *dck = d * fv;
        }
    }
}

// The passes as `pulp` kernels: each is compiled for the CPU's widest vectors at run time
// (the workspace targets baseline x86-64). A closure handed to `dispatch` was not inlined
// into the vectorised context, and its fused multiply-adds became calls to `fmaf`.

struct CellUpdate<'a> {
    c: usize,
    gates: &'a mut [f32],
    cell: &'a mut [f32],
    cell_prev: &'a [f32],
    y: Option<&'a mut [f32]>,
    skip: Option<&'a [f32]>,
    unit: f32,
}

impl pulp::WithSimd for CellUpdate<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        cell_forward_rows(
            self.c,
            self.gates,
            self.cell,
            self.cell_prev,
            self.y,
            self.skip,
            self.unit,
        )
    }
}

struct HiddenUpdate<'a> {
    c: usize,
    gates: &'a mut [f32],
    cell: &'a [f32],
    h: &'a mut [f32],
}

impl pulp::WithSimd for HiddenUpdate<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        hidden_forward_rows(self.c, self.gates, self.cell, self.h)
    }
}

struct HiddenBackward<'a> {
    c: usize,
    gates: &'a mut [f32],
    cell: &'a [f32],
    dh: &'a [f32],
    dc: &'a mut [f32],
}

impl pulp::WithSimd for HiddenBackward<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        hidden_backward_rows(self.c, self.gates, self.cell, self.dh, self.dc)
    }
}

struct CellBackward<'a> {
    c: usize,
    gates: &'a mut [f32],
    cell_prev: &'a [f32],
    dc: &'a mut [f32],
    dy: Option<&'a [f32]>,
    unit: f32,
}

impl pulp::WithSimd for CellBackward<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        cell_backward_rows(self.c, self.gates, self.cell_prev, self.dc, self.dy, self.unit)
    }
}
