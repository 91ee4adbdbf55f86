//! A trained Alt-ConvLSTM (or baseline) rolled out outside candle, for speed (seed 001
//! §5.2 reports 22 frames per second on a GPU for the 6890-vertex body).
//!
//! One frame is about 4 GFLOP at 6890 vertices, almost all of it in the gate products, so
//! the runtime is organised around them. Every signal is a row-major `[V, channels]` f32
//! buffer: the sparse products then run over contiguous channel rows (vectorised), and the
//! products' operands and result are all row-major (a channel-major layout made the sparse
//! products scalar gathers and the frame three times slower; docs/BENCHMARKS.md). Per cell
//! and step:
//! - `Â_n X_t` and `Â_n H_{t−1}` are written side by side into one `[V, c_in + c]` buffer,
//!   so all four gates of both inputs are **one** matrix product with the stacked weights
//!   `[W_x; W_h]` (faer, on all threads), added onto the biases;
//! - the peepholes add two more products: on the previous step's watched state (kept from
//!   that step, where it was computed for the output gate) and on the new one;
//! - the gate nonlinearities, the state updates and the skip of Eq. 10 are two fused
//!   passes over the vertices, in parallel, with the vectorised activations of
//!   [`crate::fast`].
//!
//! It computes what [`AltConvNet::run`] computes without teacher forcing (tested to
//! round-off); only the arithmetic's order differs.

use faer::{Accum, MatMut, MatRef, Par};

use super::cell::{self, Peephole};
use super::model::{AltConvNet, INPUT_CHANNELS, Variant};
use crate::error::{Error, Result};
use crate::graph::NormalizedAdjacency;

/// One cell's weights as row-major f32 buffers (candle's layout).
#[derive(Debug, Clone)]
struct Weights {
    c_in: usize,
    c: usize,
    peephole: Peephole,
    /// `[c_in + c, 4c]`: `W_x` stacked over `W_h`.
    w_xh: Vec<f32>,
    bias: Vec<f32>,
    /// `[c, 2c]` and `[c, c]`.
    w_if: Option<Vec<f32>>,
    w_o: Option<Vec<f32>>,
}

/// One cell's state, each row-major `[V, c]`. `watched` is `Â_n` of what the peepholes look at (`Y`
/// or `C`) at the end of the last step.
#[derive(Debug, Clone)]
struct State {
    h: Vec<f32>,
    c: Vec<f32>,
    /// `C_{t−1}` during a step (swapped with `c` before the update).
    c_prev: Vec<f32>,
    y: Option<Vec<f32>>,
    watched: Option<Vec<f32>>,
}

/// A trained model's roll-out: [`AltConvRuntime::start`] with the initial surfaces, then
/// one [`AltConvRuntime::step`] per skinned frame.
#[derive(Debug, Clone)]
pub struct AltConvRuntime {
    variant: Variant,
    adj: NormalizedAdjacency,
    cells: Vec<Weights>,
    skips: Vec<(usize, usize)>,
    states: Vec<State>,
    /// `Ŷ_{t−1}`, `X_{t−1}` and `Y_0 − X_0`, `[V, 3]`.
    previous: Vec<f32>,
    x_previous: Vec<f32>,
    offset0: Vec<f32>,
    started: bool,
    scaling: super::model::Scaling,
    /// Scratch reused every step (allocating megabytes per cell and step cost page
    /// faults): `[Â X | Â H]` and the gates.
    xh: Vec<f32>,
    gates: Vec<f32>,
}

fn tensor_values(t: &candle_core::Tensor) -> Result<Vec<f32>> {
    Ok(t.flatten_all()?.to_vec1::<f32>()?)
}

/// `out (V × n) += a (V × k) · w (k × n)`, all row-major (`out` may be a column block
/// of a wider row-major buffer), on all threads.
fn gemm_add(out: MatMut<'_, f32>, a: &[f32], w: &[f32], k: usize) {
    let (v, n) = (out.nrows(), out.ncols());
    faer::linalg::matmul::matmul(
        out,
        Accum::Add,
        MatRef::from_row_major_slice(a, v, k),
        MatRef::from_row_major_slice(w, k, n),
        1.0,
        Par::rayon(0),
    );
}

/// Vertex rows per parallel task of the fused passes.
const ROWS_PER_TASK: usize = 512;

impl AltConvRuntime {
    /// The runtime of `net` on the mesh of `adj`.
    pub fn new(net: &AltConvNet, adj: NormalizedAdjacency) -> Result<Self> {
        let cells = net
            .cells
            .iter()
            .map(|cell| {
                let (c_in, four_c) = cell.w_x.dims2()?;
                let mut w_xh = tensor_values(&cell.w_x)?;
                w_xh.extend(tensor_values(&cell.w_h)?);
                Ok(Weights {
                    c_in,
                    c: four_c / 4,
                    peephole: cell.peephole,
                    w_xh,
                    bias: tensor_values(&cell.bias)?,
                    w_if: cell.w_if.as_ref().map(tensor_values).transpose()?,
                    w_o: cell.w_o.as_ref().map(tensor_values).transpose()?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            variant: net.variant,
            adj,
            cells,
            skips: net.skips.clone(),
            states: Vec::new(),
            previous: Vec::new(),
            x_previous: Vec::new(),
            offset0: Vec::new(),
            started: false,
            scaling: net.scaling.clone(),
            xh: Vec::new(),
            gates: Vec::new(),
        })
    }

    pub fn num_vertices(&self) -> usize {
        self.adj.num_vertices()
    }

    /// A flat surface (m) as f32, checked.
    fn surface(&self, what: &'static str, x: &[f64]) -> Result<Vec<f32>> {
        if x.len() != 3 * self.num_vertices() {
            return Err(Error::Shape {
                what,
                expected: format!("{} values", 3 * self.num_vertices()),
                got: x.len().to_string(),
            });
        }
        crate::convert::f64_to_f32(what, x)
    }

    fn adjacency_product(&self, x: &[f32], channels: usize) -> Vec<f32> {
        let mut out = vec![0.0; x.len()];
        self.adj.multiply(x, channels, &mut out);
        out
    }

    /// Starts a roll-out from the skinned surface `x0` and the tissue `y0` (flat `3V`, m),
    /// with §5.1's initial states.
    pub fn start(&mut self, x0: &[f64], y0: &[f64]) -> Result<()> {
        let x0 = self.surface("initial skinned surface", x0)?;
        let y0 = self.surface("initial tissue surface", y0)?;
        let v = self.num_vertices();
        self.offset0 = y0.iter().zip(&x0).map(|(y, x)| y - x).collect();
        let out = self.cells.len() - 1;
        self.states = self
            .cells
            .iter()
            .enumerate()
            .map(|(l, w)| {
                let mut s = State {
                    h: vec![0.0; v * w.c],
                    c: vec![0.0; v * w.c],
                    c_prev: vec![0.0; v * w.c],
                    y: (w.peephole == Peephole::Accumulation).then(|| vec![0.0; v * w.c]),
                    watched: None,
                };
                if l == out {
                    match self.variant {
                        Variant::Alt => s.y = Some(y0.clone()),
                        v if v.outputs_position() => {
                            s.c = self.offset0.iter().map(|o| o / self.scaling.output as f32).collect()
                        }
                        _ => {}
                    }
                }
                s.watched = match w.peephole {
                    Peephole::Accumulation => s.y.as_ref().map(|y| self.adjacency_product(y, w.c)),
                    Peephole::Cell => Some(self.adjacency_product(&s.c, w.c)),
                    Peephole::None => None,
                };
                s
            })
            .collect();
        self.previous = y0;
        self.x_previous = x0;
        self.started = true;
        Ok(())
    }

    /// Advances one frame with the skinned surface `x_t` (flat `3V`, m); returns the
    /// predicted tissue surface `Ŷ_t`.
    pub fn step(&mut self, x_t: &[f64]) -> Result<Vec<f64>> {
        self.step_from(x_t, None)
    }

    /// [`AltConvRuntime::step`]; with `previous_truth`, the true tissue surface of the
    /// previous frame, the step starts from it instead of the model's own prediction
    /// (teacher forcing, as in training and the single-step error).
    pub fn step_from(&mut self, x_t: &[f64], previous_truth: Option<&[f64]>) -> Result<Vec<f64>> {
        if !self.started {
            return Err(Error::InvalidParameter {
                name: "Alt-ConvLSTM runtime",
                value: "step before start".into(),
                reason: "call start with the initial surfaces first",
            });
        }
        let xt = self.surface("skinned surface", x_t)?;
        if let Some(truth) = previous_truth {
            let truth = self.surface("previous true tissue surface", truth)?;
            let out = self.cells.len() - 1;
            let unit = self.scaling.output as f32;
            match self.variant {
                Variant::Alt => self.states[out].y = Some(truth.clone()),
                v if v.outputs_position() => {
                    self.states[out].c = truth
                        .iter()
                        .zip(&self.x_previous)
                        .map(|(y, x)| (y - x) / unit)
                        .collect()
                }
                _ => {}
            }
            // The peepholes' view of the replaced state.
            let watched = match self.cells[out].peephole {
                Peephole::Accumulation => self.states[out].y.as_deref(),
                Peephole::Cell => Some(self.states[out].c.as_slice()),
                Peephole::None => None,
            }
            .map(|x| self.adjacency_product(x, 3));
            if watched.is_some() {
                self.states[out].watched = watched;
            }
            self.previous = truth;
        }
        let v = self.num_vertices();
        let dx: Vec<f32> = xt.iter().zip(&self.x_previous).map(|(a, b)| a - b).collect();
        // [X_t, X_t − X_{t−1}, Y₀ − X₀] per vertex.
        // Standardised as the network was trained (`Scaling`).
        let mean = self.scaling.input_mean.map(|m| m as f32);
        let inv_std = self.scaling.input_std.map(|s| (1.0 / s) as f32);
        let mut input = vec![0.0; INPUT_CHANNELS * v];
        cell::standardized_input(&xt, &dx, &self.offset0, &mean, &inv_std, &mut input);
        let unit = self.scaling.output as f32;
        let out = self.cells.len() - 1;
        for l in 0..self.cells.len() {
            let w = &self.cells[l];
            let (c_in, c) = (w.c_in, w.c);
            let k = c_in + c;
            // [Â X_t | Â H_{t−1}] row by row, then every gate on its bias in one product.
            let (states_below, states_here) = self.states.split_at_mut(l);
            let state = &mut states_here[0];
            let below: &[f32] = match states_below.last() {
                Some(s) => &s.c,
                None => &input,
            };
            self.xh.resize(v * k, 0.0);
            let xh = &mut self.xh[..v * k];
            self.adj.multiply_into(below, c_in, xh, k, 0);
            self.adj.multiply_into(&state.h, c, xh, k, c_in);
            self.gates.clear();
            for _ in 0..v {
                self.gates.extend_from_slice(&w.bias);
            }
            let mut g = MatMut::from_row_major_slice_mut(&mut self.gates, v, 4 * c);
            gemm_add(g.as_mut(), xh, &w.w_xh, k);
            if let (Some(w_if), Some(watched)) = (&w.w_if, &state.watched) {
                gemm_add(g.as_mut().subcols_mut(0, 2 * c), watched, w_if, c);
            }
            let skip: Option<&[f32]> = if l == out {
                (self.variant == Variant::Alt).then_some(dx.as_slice())
            } else {
                self.skips
                    .iter()
                    .find(|(to, _)| *to == l)
                    .map(|(_, from)| states_below[*from].c.as_slice())
            };
            // Eq. 5, lines 1–4: C_{t−1} moves to `c_prev`, C_t is written into `c`.
            std::mem::swap(&mut state.c, &mut state.c_prev);
            cell::cell_forward(
                ROWS_PER_TASK,
                c,
                &mut self.gates,
                &mut state.c,
                &state.c_prev,
                state.y.as_deref_mut(),
                skip,
                if l == out { unit } else { 1.0 },
            );
            // Â of what the peepholes watch, now: the output gate's, and the input and
            // forget gates' at the next step.
            let watched_now = match w.peephole {
                Peephole::Accumulation => state.y.as_deref(),
                Peephole::Cell => Some(state.c.as_slice()),
                Peephole::None => None,
            };
            if let (Some(x), Some(watched)) = (watched_now, state.watched.as_mut()) {
                self.adj.multiply(x, c, watched);
            }
            if let (Some(w_o), Some(watched)) = (&w.w_o, &state.watched) {
                let mut g = MatMut::from_row_major_slice_mut(&mut self.gates, v, 4 * c);
                gemm_add(g.as_mut().subcols_mut(3 * c, c), watched, w_o, c);
            }
            // Lines 5–6.
            cell::hidden_forward(ROWS_PER_TASK, c, &mut self.gates, &state.c, &mut state.h);
        }
        let c_out = &self.states[out].c;
        let y_out = self.states[out].y.as_deref();
        let prediction = cell::readout(self.variant, y_out, c_out, &xt, &self.previous, &dx, unit);
        if let Some(index) = prediction.iter().position(|p| !p.is_finite()) {
            return Err(Error::NonFinite {
                what: "Alt-ConvLSTM prediction",
                index,
            });
        }
        self.previous = prediction.clone();
        self.x_previous = xt;
        Ok(prediction.into_iter().map(f64::from).collect())
    }
}
