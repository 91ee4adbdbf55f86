//! The fused training path of Alt-ConvLSTM and the four ConvLSTM baselines: a whole
//! teacher-forced sequence — forward through every cell and step, and its backward pass
//! through time — as **one** candle custom op with a hand-written backward pass.
//!
//! candle's autograd records every small tensor operation of [`AltConvNet::run_forced`]
//! (about forty per cell and step), allocates each result and walks the graph back
//! operation by operation; most of a training pass went there (docs/BENCHMARKS.md). Here
//! the op's only differentiable input is the flat parameter vector θ (every cell's weights
//! concatenated, [`AltConvNet::flat_parameters`]); its output is the predicted surfaces
//! `[B, T, V, 3]`, so Eq. 12's loss and everything after it stay in candle.
//!
//! Forward, per step and cell (rows are the `B·V` vertices of the batch, row-major):
//! - `[Â X_t | Â H_{t−1}]` side by side, then all four gates in one matrix product with
//!   `[W_x; W_h]` onto the bias, plus the peepholes' products on `Â` of the watched state
//!   (`Y` for Alt-ConvLSTM, `C` for the CP baselines) before and after the update;
//! - the gate nonlinearities and Eq. 5's updates in two fused passes over the rows.
//!
//! The tape keeps what the backward pass needs: the gate operands `[Â X | Â H]`, the
//! activated gates, every cell state and the peepholes' operands. The backward pass runs
//! the steps and cells in reverse, carrying `∂L/∂H`, `∂L/∂C` and `∂L/∂Y` of every cell;
//! each step's gate gradients overwrite the activated gates in the tape, so the weight
//! gradients are **one** product per weight over all steps at the end
//! (`∂L/∂W = Σ_t A_tᵀ ∂L/∂G_t` with the steps stacked). `Â_n` is symmetric, so the
//! gradient through a graph convolution is the same sparse product.
//!
//! Teacher forcing replaces a state by the truth: no gradient flows into the replaced
//! state (the candle path's replaced tensor is a constant likewise).
//!
//! The tape and every buffer live in a [`FusedWorkspace`] reused from one batch to the
//! next: allocating a few hundred megabytes per pass cost page faults (a third of the
//! autograd path's time was system time).
//!
//! The gradients equal the autograd path's to round-off (tests: every variant, every
//! parameter, teacher forcing and scheduled sampling, a batch).

use std::sync::{Arc, Mutex};

use candle_core::{CpuStorage, Layout, Shape, Tensor};
use faer::{Accum, MatMut, MatRef, Par};
use rayon::prelude::*;

use super::cell::{self, Peephole};
use super::model::{AltConvNet, Drive, INPUT_CHANNELS, Variant};
use crate::error::{Error, Result};
use crate::graph::{Columns, NormalizedAdjacency};

/// One cell's shape and where its parameters sit in θ.
#[derive(Debug, Clone)]
struct CellPlan {
    c_in: usize,
    c: usize,
    peephole: Peephole,
    /// Offsets into θ of `[W_x; W_h]` (`[c_in + c, 4c]` row-major: `W_x` then `W_h`), the
    /// bias `[4c]`, `W_if` `[c, 2c]` and `W_o` `[c, c]` (the last two with a peephole).
    w_xh: usize,
    bias: usize,
    w_if: usize,
    w_o: usize,
    /// The cell whose state Eq. 10 adds to this cell's accumulation.
    skip_from: Option<usize>,
    /// The cell state's unit in the accumulation's (the output cell's is the scaling's).
    unit: f32,
}

impl CellPlan {
    fn k(&self) -> usize {
        self.c_in + self.c
    }
}

/// The network's structure, as the kernels read it.
#[derive(Debug, Clone)]
struct Plan {
    variant: Variant,
    cells: Vec<CellPlan>,
    num_params: usize,
    /// Output unit (m) and the input standardisation ([`super::model::Scaling`]).
    unit: f32,
    mean: [f32; INPUT_CHANNELS],
    inv_std: [f32; INPUT_CHANNELS],
}

impl Plan {
    fn new(net: &AltConvNet) -> Result<Self> {
        let out = net.cells.len() - 1;
        let unit = net.scaling.output as f32;
        let mut offset = 0;
        let mut cells = Vec::with_capacity(net.cells.len());
        for (l, cell) in net.cells.iter().enumerate() {
            let (c_in, four_c) = cell.w_x.dims2()?;
            let c = four_c / 4;
            let w_xh = offset;
            offset += (c_in + c) * 4 * c;
            let bias = offset;
            offset += 4 * c;
            let (w_if, w_o) = if cell.peephole == Peephole::None {
                (offset, offset)
            } else {
                let w_if = offset;
                offset += 2 * c * c;
                let w_o = offset;
                offset += c * c;
                (w_if, w_o)
            };
            cells.push(CellPlan {
                c_in,
                c,
                peephole: cell.peephole,
                w_xh,
                bias,
                w_if,
                w_o,
                skip_from: net.skips.iter().find(|(to, _)| *to == l).map(|(_, from)| *from),
                unit: if l == out { unit } else { 1.0 },
            });
        }
        Ok(Self {
            variant: net.variant,
            cells,
            num_params: offset,
            unit,
            mean: net.scaling.input_mean.map(|m| m as f32),
            inv_std: net.scaling.input_std.map(|s| (1.0 / s) as f32),
        })
    }

    fn out(&self) -> usize {
        self.cells.len() - 1
    }

    /// Whether teacher forcing replaces the output cell's state (and so cuts a
    /// gradient inside the cell): Alt-ConvLSTM's accumulation, the `-Y` baselines' state.
    fn replaces_out_state(&self) -> bool {
        self.variant == Variant::Alt || self.variant.outputs_position()
    }
}

impl AltConvNet {
    /// Every cell's parameters, flattened and concatenated in the fused op's layout (per
    /// cell: `W_x`, `W_h`, bias, then `W_if` and `W_o` with a peephole). Differentiable:
    /// the gradient of θ flows back to each parameter.
    pub fn flat_parameters(&self) -> Result<Tensor> {
        let mut parts = Vec::new();
        for cell in &self.cells {
            parts.push(cell.w_x.flatten_all()?);
            parts.push(cell.w_h.flatten_all()?);
            parts.push(cell.bias.flatten_all()?);
            for w in [&cell.w_if, &cell.w_o].into_iter().flatten() {
                parts.push(w.flatten_all()?);
            }
        }
        Ok(Tensor::cat(&parts, 0)?)
    }

    /// [`AltConvNet::run_forced`] as one fused op: the predicted surfaces
    /// `[B, steps, V, 3]`, differentiable with respect to every parameter through the
    /// op's hand-written backward pass. `forced[t]` (length `steps + 1`) says whether step
    /// `t > 1` starts from the truth. `workspace` holds the tape between this forward pass
    /// and its backward pass, and the buffers reused by the next call.
    pub fn run_fused(
        &self,
        adj: &NormalizedAdjacency,
        drive: &Drive,
        truth: Option<&Tensor>,
        steps: usize,
        forced: &[bool],
        workspace: &FusedWorkspace,
    ) -> Result<Tensor> {
        let data = Sequences::new(adj, drive, truth, steps, forced)?;
        let plan = Plan::new(self)?;
        let theta = self.flat_parameters()?;
        if theta.elem_count() != plan.num_params {
            return Err(Error::Shape {
                what: "Alt-ConvLSTM parameters",
                expected: plan.num_params.to_string(),
                got: theta.elem_count().to_string(),
            });
        }
        let generation = {
            let mut inner = workspace.lock()?;
            inner.next_generation += 1;
            inner.next_generation
        };
        let op = SequenceOp {
            plan: Arc::new(plan),
            adj: adj.clone(),
            data: Arc::new(data),
            workspace: workspace.clone(),
            generation,
        };
        Ok(theta.apply_op1(op)?)
    }
}

/// The buffers of the fused path, reused across calls; one per training run (cheap to
/// clone: clones share the buffers). A backward pass must follow its own forward pass
/// before the next forward pass through the same workspace (the trainer's order); a
/// stale one is an error, never wrong gradients.
#[derive(Debug, Clone, Default)]
pub struct FusedWorkspace {
    inner: Arc<Mutex<Inner>>,
}

impl FusedWorkspace {
    pub fn new() -> Self {
        Self::default()
    }

    fn lock(&self) -> Result<std::sync::MutexGuard<'_, Inner>> {
        self.inner.lock().map_err(|_| Error::InvalidParameter {
            name: "fused Alt-ConvLSTM workspace",
            value: "poisoned".into(),
            reason: "a thread panicked while holding it",
        })
    }
}

#[derive(Debug, Default)]
struct Inner {
    next_generation: u64,
    /// The generation of the forward pass the tape holds.
    taped: u64,
    cells: Vec<CellTape>,
}

/// One cell's tape (`T` steps of `R` rows) and running state.
#[derive(Debug, Default)]
struct CellTape {
    /// `[T, R, c_in + c]`: the gate operands `[Â X_t | Â H_{t−1}]`.
    xh: Vec<f32>,
    /// `[T, R, 4c]`: the activated gates i, f, c̃, o; the backward pass overwrites each
    /// step's with the gradient of the pre-activations.
    gates: Vec<f32>,
    /// `[T + 1, R, c]`: `C_0 … C_T`.
    cell: Vec<f32>,
    /// `[T + 1, R, c]`: `Â` of the watched state after each step (with a peephole).
    watched: Vec<f32>,
    /// The output cell only, where teacher forcing may replace its state: `[T, R, c]`,
    /// the previous state and its `Â` that step `t` actually used.
    cell_used: Vec<f32>,
    watched_used: Vec<f32>,
    /// Running `H` and `Y`, `[R, c]`.
    h: Vec<f32>,
    y: Vec<f32>,
}

/// The sequences of one call, per step as `[R, 3]` rows (f32, m).
#[derive(Debug)]
struct Sequences {
    batch: usize,
    vertices: usize,
    steps: usize,
    /// `x[t]`, `t = 0..=steps`.
    skinned: Vec<Vec<f32>>,
    truth: Option<Vec<Vec<f32>>>,
    initial: Vec<f32>,
    forced: Vec<bool>,
}

impl Sequences {
    fn new(
        adj: &NormalizedAdjacency,
        drive: &Drive,
        truth: Option<&Tensor>,
        steps: usize,
        forced: &[bool],
    ) -> Result<Self> {
        let (b, frames, v, three) = drive.skinned.dims4()?;
        if three != 3 || v != adj.num_vertices() || drive.initial.dims() != [b, v, 3] {
            return Err(Error::Shape {
                what: "Alt-ConvLSTM drive",
                expected: format!(
                    "skinned [B, T+1, {v}, 3] and initial [B, {v}, 3]",
                    v = adj.num_vertices()
                ),
                got: format!("{:?} and {:?}", drive.skinned.dims(), drive.initial.dims()),
            });
        }
        if steps == 0 || steps >= frames {
            return Err(Error::InvalidParameter {
                name: "Alt-ConvLSTM steps",
                value: steps.to_string(),
                reason: "needs at least one step and one more skinned frame than steps",
            });
        }
        if forced.len() != steps + 1 {
            return Err(Error::Shape {
                what: "teacher-forcing mask",
                expected: (steps + 1).to_string(),
                got: forced.len().to_string(),
            });
        }
        if let Some(t) = truth {
            if t.dims() != drive.skinned.dims() {
                return Err(Error::Shape {
                    what: "Alt-ConvLSTM truth",
                    expected: format!("{:?}", drive.skinned.dims()),
                    got: format!("{:?}", t.dims()),
                });
            }
        }
        let per_step = |x: &Tensor| -> Result<Vec<Vec<f32>>> {
            let all: Vec<f32> = x.narrow(1, 0, steps + 1)?.flatten_all()?.to_vec1()?;
            let frame = v * 3;
            Ok((0..=steps)
                .map(|t| {
                    (0..b)
                        .flat_map(|s| all[(s * (steps + 1) + t) * frame..][..frame].iter().copied())
                        .collect()
                })
                .collect())
        };
        Ok(Self {
            batch: b,
            vertices: v,
            steps,
            skinned: per_step(&drive.skinned)?,
            truth: truth.map(per_step).transpose()?,
            initial: drive.initial.flatten_all()?.to_vec1()?,
            forced: forced.to_vec(),
        })
    }

    fn rows(&self) -> usize {
        self.batch * self.vertices
    }

    /// Whether step `t` starts from the true previous surface.
    fn replaced(&self, t: usize) -> bool {
        t > 1 && self.forced[t] && self.truth.is_some()
    }
}

/// The op: θ in, predicted surfaces `[B, T, V, 3]` out.
struct SequenceOp {
    plan: Arc<Plan>,
    adj: NormalizedAdjacency,
    data: Arc<Sequences>,
    workspace: FusedWorkspace,
    generation: u64,
}

fn candle_error(e: Error) -> candle_core::Error {
    candle_core::Error::Msg(format!("fused Alt-ConvLSTM: {e}"))
}

impl candle_core::CustomOp1 for SequenceOp {
    fn name(&self) -> &'static str {
        "fused-altconv-sequence"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let all = storage.as_slice::<f32>()?;
        let (a, b) = layout
            .contiguous_offsets()
            .ok_or_else(|| candle_core::Error::Msg("fused Alt-ConvLSTM: θ must be contiguous".into()))?;
        let theta = &all[a..b];
        let mut inner = self.workspace.lock().map_err(candle_error)?;
        let predictions = forward(&self.plan, &self.adj, theta, &self.data, &mut inner.cells);
        inner.taped = self.generation;
        let d = &self.data;
        let mut out = vec![0.0f32; d.batch * d.steps * d.vertices * 3];
        let frame = d.vertices * 3;
        for (t, p) in predictions.iter().enumerate() {
            for s in 0..d.batch {
                out[(s * d.steps + t) * frame..][..frame].copy_from_slice(&p[s * frame..][..frame]);
            }
        }
        Ok((CpuStorage::F32(out), Shape::from((d.batch, d.steps, d.vertices, 3))))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let theta: Vec<f32> = arg.flatten_all()?.to_vec1()?;
        let grad: Vec<f32> = grad_res.flatten_all()?.to_vec1()?;
        let d = &self.data;
        let frame = d.vertices * 3;
        let d_pred: Vec<Vec<f32>> = (0..d.steps)
            .map(|t| {
                (0..d.batch)
                    .flat_map(|s| grad[(s * d.steps + t) * frame..][..frame].iter().copied())
                    .collect()
            })
            .collect();
        let mut inner = self.workspace.lock().map_err(candle_error)?;
        if inner.taped != self.generation {
            return Err(candle_error(Error::InvalidParameter {
                name: "fused Alt-ConvLSTM backward pass",
                value: format!("tape of pass {}, asked for pass {}", inner.taped, self.generation),
                reason: "another forward pass through the same workspace overwrote the tape; run backward before the next forward",
            }));
        }
        let d_theta = backward(&self.plan, &self.adj, &theta, d, &mut inner.cells, &d_pred);
        Ok(Some(Tensor::from_vec(d_theta, arg.shape(), arg.device())?))
    }
}

/// Rows per parallel task of the fused passes.
const ROWS_PER_TASK: usize = 256;

/// `out (Accum) a · b` on all threads.
fn gemm(out: MatMut<'_, f32>, accum: Accum, a: MatRef<'_, f32>, b: MatRef<'_, f32>) {
    faer::linalg::matmul::matmul(out, accum, a, b, 1.0, Par::rayon(0));
}

/// A row-major `[rows, cols]` view of `data`.
fn view(data: &[f32], rows: usize, cols: usize) -> MatRef<'_, f32> {
    MatRef::from_row_major_slice(data, rows, cols)
}

fn view_mut(data: &mut [f32], rows: usize, cols: usize) -> MatMut<'_, f32> {
    MatMut::from_row_major_slice_mut(data, rows, cols)
}

struct AddScaled<'a> {
    a: &'a mut [f32],
    b: &'a [f32],
    s: f32,
}

impl pulp::WithSimd for AddScaled<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        for (x, y) in self.a.iter_mut().zip(self.b) {
            *x += self.s * y;
        }
    }
}

/// `a += s · b` elementwise, in parallel.
fn add_scaled(a: &mut [f32], b: &[f32], s: f32) {
    a.par_chunks_mut(1 << 14)
        .zip(b.par_chunks(1 << 14))
        .for_each(|(a, b)| pulp::Arch::new().dispatch(AddScaled { a, b, s }));
}

/// Sizes every buffer of the tape for `rows` rows and `steps` steps (contents are
/// overwritten by the forward pass before they are read).
fn prepare(plan: &Plan, cells: &mut Vec<CellTape>, rows: usize, steps: usize) {
    cells.resize_with(plan.cells.len(), CellTape::default);
    let out = plan.out();
    for (l, (p, tape)) in plan.cells.iter().zip(cells.iter_mut()).enumerate() {
        let c = p.c;
        tape.xh.resize(steps * rows * p.k(), 0.0);
        tape.gates.resize(steps * rows * 4 * c, 0.0);
        tape.cell.resize((steps + 1) * rows * c, 0.0);
        let peephole = p.peephole != Peephole::None;
        tape.watched
            .resize(if peephole { (steps + 1) * rows * c } else { 0 }, 0.0);
        let replaced = l == out && plan.replaces_out_state();
        tape.cell_used.resize(if replaced { steps * rows * c } else { 0 }, 0.0);
        tape.watched_used
            .resize(if replaced && peephole { steps * rows * c } else { 0 }, 0.0);
        tape.h.clear();
        tape.h.resize(rows * c, 0.0);
        tape.y.clear();
        tape.y.resize(
            if p.peephole == Peephole::Accumulation {
                rows * c
            } else {
                0
            },
            0.0,
        );
    }
}

/// The forward pass; fills the tape and returns the predictions `Ŷ_1..Ŷ_T`, `[R, 3]` each.
fn forward(
    plan: &Plan,
    adj: &NormalizedAdjacency,
    theta: &[f32],
    data: &Sequences,
    cells: &mut Vec<CellTape>,
) -> Vec<Vec<f32>> {
    let (rows, steps) = (data.rows(), data.steps);
    prepare(plan, cells, rows, steps);
    let out = plan.out();
    let unit = plan.unit;
    let x0 = &data.skinned[0];
    let offset0: Vec<f32> = data.initial.iter().zip(x0).map(|(y, x)| y - x).collect();
    // §5.1's initial states: zeros, but the output cell's accumulation Y_0 (Alt-ConvLSTM)
    // or offset state (Y_0 − X_0)/unit (the -Y baselines).
    for (p, tape) in plan.cells.iter().zip(cells.iter_mut()) {
        let n = rows * p.c;
        tape.cell[..n].fill(0.0);
    }
    match plan.variant {
        Variant::Alt => cells[out].y.copy_from_slice(&data.initial),
        v if v.outputs_position() => {
            for (c, o) in cells[out].cell[..rows * 3].iter_mut().zip(&offset0) {
                *c = o / unit;
            }
        }
        _ => {}
    }
    for (p, tape) in plan.cells.iter().zip(cells.iter_mut()) {
        let n = rows * p.c;
        let CellTape { cell, watched, y, .. } = tape;
        match p.peephole {
            Peephole::Accumulation => adj.multiply(y, p.c, &mut watched[..n]),
            Peephole::Cell => adj.multiply(&cell[..n], p.c, &mut watched[..n]),
            Peephole::None => {}
        }
    }
    let mut previous = data.initial.clone();
    let mut input = vec![0.0f32; rows * INPUT_CHANNELS];
    let mut predictions = Vec::with_capacity(steps);
    for t in 1..=steps {
        let (xt, x_prev) = (&data.skinned[t], &data.skinned[t - 1]);
        let dx: Vec<f32> = xt.iter().zip(x_prev).map(|(a, b)| a - b).collect();
        // The output cell's previous state: the truth where teacher forcing replaces it.
        if plan.replaces_out_state() {
            let p = &plan.cells[out];
            let n = rows * p.c;
            let tape = &mut cells[out];
            let replaced = data.replaced(t);
            let truth = data.truth.as_ref().map(|tr| &tr[t - 1]);
            let (used, _) = tape.cell_used.split_at_mut(t * n);
            let used = &mut used[(t - 1) * n..];
            match (replaced, plan.variant, truth) {
                (true, Variant::Alt, Some(y)) => {
                    tape.y.copy_from_slice(y);
                    used.copy_from_slice(&tape.cell[(t - 1) * n..t * n]);
                }
                (true, _, Some(y)) => {
                    for ((u, yv), xv) in used.iter_mut().zip(y).zip(x_prev) {
                        *u = (yv - xv) / unit;
                    }
                }
                _ => used.copy_from_slice(&tape.cell[(t - 1) * n..t * n]),
            }
            if p.peephole != Peephole::None {
                let (wu, _) = tape.watched_used.split_at_mut(t * n);
                let wu = &mut wu[(t - 1) * n..];
                if replaced {
                    match p.peephole {
                        Peephole::Accumulation => adj.multiply(&tape.y, p.c, wu),
                        _ => adj.multiply(&tape.cell_used[(t - 1) * n..t * n], p.c, wu),
                    }
                } else {
                    wu.copy_from_slice(&tape.watched[(t - 1) * n..t * n]);
                }
            }
        }
        if plan.variant != Variant::Alt && !plan.variant.outputs_position() && data.replaced(t) {
            if let Some(tr) = &data.truth {
                previous.copy_from_slice(&tr[t - 1]);
            }
        }
        cell::standardized_input(xt, &dx, &offset0, &plan.mean, &plan.inv_std, &mut input);
        for l in 0..=out {
            let p = &plan.cells[l];
            let (c_in, c, k) = (p.c_in, p.c, p.k());
            let n = rows * c;
            let (below, here) = cells.split_at_mut(l);
            let CellTape {
                xh,
                gates,
                cell,
                watched,
                cell_used,
                watched_used,
                h,
                y,
            } = &mut here[0];
            let below_state: &[f32] = match below.last() {
                Some(b) => &b.cell[t * rows * c_in..(t + 1) * rows * c_in],
                None => &input,
            };
            // [Â X_t | Â H_{t−1}], then every gate on its bias in one product.
            let xh = &mut xh[(t - 1) * rows * k..t * rows * k];
            adj.product(Columns::whole(below_state, c_in), c_in, xh, k, 0, false);
            adj.product(Columns::whole(h, c), c, xh, k, c_in, false);
            let bias = &theta[p.bias..p.bias + 4 * c];
            let gates = &mut gates[(t - 1) * rows * 4 * c..t * rows * 4 * c];
            gates.par_chunks_mut(4 * c).for_each(|g| g.copy_from_slice(bias));
            let w_xh = view(&theta[p.w_xh..p.w_xh + k * 4 * c], k, 4 * c);
            gemm(view_mut(gates, rows, 4 * c), Accum::Add, view(xh, rows, k), w_xh);
            let (cell_before, cell_after) = cell.split_at_mut(t * n);
            let cell_t = &mut cell_after[..n];
            let cell_prev: &[f32] = if cell_used.is_empty() {
                &cell_before[(t - 1) * n..]
            } else {
                &cell_used[(t - 1) * n..t * n]
            };
            if p.peephole != Peephole::None {
                let w_if = view(&theta[p.w_if..p.w_if + 2 * c * c], c, 2 * c);
                let wp: &[f32] = if watched_used.is_empty() {
                    &watched[(t - 1) * n..t * n]
                } else {
                    &watched_used[(t - 1) * n..t * n]
                };
                gemm(
                    view_mut(gates, rows, 4 * c).subcols_mut(0, 2 * c),
                    Accum::Add,
                    view(wp, rows, c),
                    w_if,
                );
            }
            // Lines 1–4.
            let skip: Option<&[f32]> = if l == out {
                (plan.variant == Variant::Alt).then_some(dx.as_slice())
            } else {
                p.skip_from.map(|f| &below[f].cell[t * n..(t + 1) * n])
            };
            let y_now = (!y.is_empty()).then_some(y.as_mut_slice());
            cell::cell_forward(ROWS_PER_TASK, c, gates, cell_t, cell_prev, y_now, skip, p.unit);
            let cell_t = &cell_after[..n];
            // Â of the watched state now, and the output gate's peephole on it.
            if p.peephole != Peephole::None {
                let w_now = &mut watched[t * n..(t + 1) * n];
                match p.peephole {
                    Peephole::Accumulation => adj.multiply(y, c, w_now),
                    _ => adj.multiply(cell_t, c, w_now),
                }
                let w_o = view(&theta[p.w_o..p.w_o + c * c], c, c);
                gemm(
                    view_mut(gates, rows, 4 * c).subcols_mut(3 * c, c),
                    Accum::Add,
                    view(w_now, rows, c),
                    w_o,
                );
            }
            // Lines 5–6.
            cell::hidden_forward(ROWS_PER_TASK, c, gates, cell_t, h);
        }
        let c_out = &cells[out].cell[t * rows * 3..(t + 1) * rows * 3];
        let y_out = (plan.variant == Variant::Alt).then_some(cells[out].y.as_slice());
        let prediction = cell::readout(plan.variant, y_out, c_out, xt, &previous, &dx, unit);
        previous.copy_from_slice(&prediction);
        predictions.push(prediction);
    }
    predictions
}

/// The backward pass through the taped forward pass, from `∂L/∂Ŷ_t` (`[R, 3]` per step)
/// to `∂L/∂θ`.
fn backward(
    plan: &Plan,
    adj: &NormalizedAdjacency,
    theta: &[f32],
    data: &Sequences,
    cells: &mut [CellTape],
    d_pred: &[Vec<f32>],
) -> Vec<f32> {
    let (rows, steps) = (data.rows(), data.steps);
    let out = plan.out();
    let unit = plan.unit;
    let widths: Vec<usize> = plan.cells.iter().map(|p| p.c).collect();
    let mut dh: Vec<Vec<f32>> = widths.iter().map(|c| vec![0.0; rows * c]).collect();
    let mut dc: Vec<Vec<f32>> = widths.iter().map(|c| vec![0.0; rows * c]).collect();
    let mut dy: Vec<Vec<f32>> = plan
        .cells
        .iter()
        .map(|p| {
            if p.peephole == Peephole::Accumulation {
                vec![0.0; rows * p.c]
            } else {
                Vec::new()
            }
        })
        .collect();
    let max_k = plan.cells.iter().map(|p| p.k()).max().unwrap_or(0);
    let max_c = widths.iter().copied().max().unwrap_or(0);
    let mut dxh = vec![0.0f32; rows * max_k];
    let mut tmp = vec![0.0f32; rows * max_c];
    // ∂L/∂Ŷ_{t−1} through the ΔY baselines' `Ŷ_t = Ŷ_{t−1} + …`.
    let mut d_previous = vec![0.0f32; rows * 3];
    for t in (1..=steps).rev() {
        let replaced = data.replaced(t);
        match plan.variant {
            Variant::Alt => add_scaled(&mut dy[out], &d_pred[t - 1], 1.0),
            v if v.outputs_position() => add_scaled(&mut dc[out], &d_pred[t - 1], unit),
            _ => {
                for (d, g) in d_previous.iter_mut().zip(&d_pred[t - 1]) {
                    *d += g;
                }
                add_scaled(&mut dc[out], &d_previous, unit);
                if t == 1 || replaced {
                    d_previous.fill(0.0);
                }
            }
        }
        for l in (0..=out).rev() {
            let p = &plan.cells[l];
            let (c_in, c, k) = (p.c_in, p.c, p.k());
            let n = rows * c;
            let CellTape {
                gates, cell, cell_used, ..
            } = &mut cells[l];
            let gates = &mut gates[(t - 1) * rows * 4 * c..t * rows * 4 * c];
            let cell_t = &cell[t * n..(t + 1) * n];
            let cell_prev: &[f32] = if cell_used.is_empty() {
                &cell[(t - 1) * n..t * n]
            } else {
                &cell_used[(t - 1) * n..t * n]
            };
            // Line 6.
            cell::hidden_backward(ROWS_PER_TASK, c, gates, cell_t, &dh[l], &mut dc[l]);
            // The output gate's peephole on Â of the new watched state (Y_t or C_t).
            if p.peephole != Peephole::None {
                let w_o = view(&theta[p.w_o..p.w_o + c * c], c, c);
                let tmp = &mut tmp[..n];
                gemm(
                    view_mut(tmp, rows, c),
                    Accum::Replace,
                    view(gates, rows, 4 * c).subcols(3 * c, c),
                    w_o.transpose(),
                );
                let target: &mut [f32] = match p.peephole {
                    Peephole::Accumulation => &mut dy[l],
                    _ => &mut dc[l],
                };
                adj.product(Columns::whole(tmp, c), c, target, c, 0, true);
            }
            // Eq. 10's skip: the accumulation's gradient reaches the skipped cell's state.
            if let Some(from) = p.skip_from {
                add_scaled(&mut dc[from], &dy[l], 1.0);
            }
            // Lines 1–4, and the carry of ∂L/∂C to the previous step.
            let dy_l: Option<&[f32]> = (!dy[l].is_empty()).then_some(dy[l].as_slice());
            cell::cell_backward(ROWS_PER_TASK, c, gates, cell_prev, &mut dc[l], dy_l, p.unit);
            // Teacher forcing replaced the previous state: nothing flows into it.
            let cut = l == out && replaced && plan.replaces_out_state();
            if cut {
                match plan.variant {
                    Variant::Alt => dy[l].fill(0.0),
                    _ => dc[l].fill(0.0),
                }
            }
            // The input and forget gates' peepholes on Â of the previous watched state.
            if p.peephole != Peephole::None && !cut {
                let w_if = view(&theta[p.w_if..p.w_if + 2 * c * c], c, 2 * c);
                let tmp = &mut tmp[..n];
                gemm(
                    view_mut(tmp, rows, c),
                    Accum::Replace,
                    view(gates, rows, 4 * c).subcols(0, 2 * c),
                    w_if.transpose(),
                );
                let target: &mut [f32] = match p.peephole {
                    Peephole::Accumulation => &mut dy[l],
                    _ => &mut dc[l],
                };
                adj.product(Columns::whole(tmp, c), c, target, c, 0, true);
            }
            // The gate operands: ∂L/∂[ÂX | ÂH] = ∂L/∂G · [W_x; W_h]ᵀ, then Â back.
            let w_xh = view(&theta[p.w_xh..p.w_xh + k * 4 * c], k, 4 * c);
            let dxh = &mut dxh[..rows * k];
            gemm(
                view_mut(dxh, rows, k),
                Accum::Replace,
                view(gates, rows, 4 * c),
                w_xh.transpose(),
            );
            let operand = |offset| Columns {
                data: dxh,
                stride: k,
                offset,
            };
            adj.product(operand(c_in), c, &mut dh[l], c, 0, false);
            if l > 0 {
                adj.product(operand(0), c_in, &mut dc[l - 1], c_in, 0, true);
            }
        }
    }
    // The weight gradients, each one product over all steps.
    let mut d_theta = vec![0.0f32; plan.num_params];
    let tr = steps * rows;
    for (p, tape) in plan.cells.iter().zip(cells.iter()) {
        let (c, k) = (p.c, p.k());
        let dg = view(&tape.gates[..tr * 4 * c], tr, 4 * c);
        gemm(
            view_mut(&mut d_theta[p.w_xh..p.w_xh + k * 4 * c], k, 4 * c),
            Accum::Replace,
            view(&tape.xh[..tr * k], tr, k).transpose(),
            dg,
        );
        let bias = &mut d_theta[p.bias..p.bias + 4 * c];
        let sums = tape.gates[..tr * 4 * c]
            .par_chunks(ROWS_PER_TASK * 4 * c)
            .map(|block| {
                let mut s = vec![0.0f64; 4 * c];
                for row in block.chunks_exact(4 * c) {
                    for (a, b) in s.iter_mut().zip(row) {
                        *a += *b as f64;
                    }
                }
                s
            })
            .reduce(
                || vec![0.0f64; 4 * c],
                |mut a, b| {
                    for (x, y) in a.iter_mut().zip(b) {
                        *x += y;
                    }
                    a
                },
            );
        for (b, s) in bias.iter_mut().zip(sums) {
            *b = s as f32;
        }
        if p.peephole != Peephole::None {
            let n = rows * c;
            let prev: &[f32] = if tape.watched_used.is_empty() {
                &tape.watched[..tr * c]
            } else {
                &tape.watched_used[..tr * c]
            };
            gemm(
                view_mut(&mut d_theta[p.w_if..p.w_if + 2 * c * c], c, 2 * c),
                Accum::Replace,
                view(prev, tr, c).transpose(),
                dg.subcols(0, 2 * c),
            );
            gemm(
                view_mut(&mut d_theta[p.w_o..p.w_o + c * c], c, c),
                Accum::Replace,
                view(&tape.watched[n..n + tr * c], tr, c).transpose(),
                dg.subcols(3 * c, c),
            );
        }
    }
    d_theta
}
