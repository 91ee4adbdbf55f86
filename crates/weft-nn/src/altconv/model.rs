//! The Alt-ConvLSTM cell (Eq. 5), its vanilla ConvLSTM variants and the network of five
//! hidden cells and an output cell (§4.3), built from candle tensor operations: the
//! autograd reference that the fused kernels ([`super::fused`]) and the runtime
//! ([`super::runtime`]) are tested against.

use candle_core::{DType, Device, Tensor};
use serde::{Deserialize, Serialize};

use super::cell::Peephole;
use crate::error::{Error, Result};
use crate::graph::NormalizedAdjacency;
use crate::params::{Init, ParamStore};

/// Channels of the first cell's input `[X_t, X_t − X_{t−1}, Y₀ − X₀]`.
pub const INPUT_CHANNELS: usize = 9;
/// The paper's hidden cells (§5.1).
pub const HIDDEN: [usize; 5] = [32, 64, 128, 64, 32];
/// Scale of the output cell's initial weights (see [`AltConvNet::new`]).
const OUTPUT_INIT_GAIN: f64 = 0.01;

/// The models of the comparison (Alt-ConvLSTM Tables 1–2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Variant {
    #[serde(rename = "alt-convlstm")]
    Alt,
    #[serde(rename = "convlstm-cp-dy")]
    CpDy,
    #[serde(rename = "convlstm-np-dy")]
    NpDy,
    #[serde(rename = "convlstm-cp-y")]
    CpY,
    #[serde(rename = "convlstm-np-y")]
    NpY,
}

impl Variant {
    pub const ALL: [Variant; 5] = [Self::Alt, Self::CpDy, Self::NpDy, Self::CpY, Self::NpY];

    /// The method's name in `results.json` and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Alt => "alt-convlstm",
            Self::CpDy => "convlstm-cp-dy",
            Self::NpDy => "convlstm-np-dy",
            Self::CpY => "convlstm-cp-y",
            Self::NpY => "convlstm-np-y",
        }
    }

    pub fn from_name(name: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|v| v.name() == name || (name == "alt" && *v == Self::Alt))
            .ok_or_else(|| Error::InvalidParameter {
                name: "Alt-ConvLSTM model",
                value: name.to_string(),
                reason: "must be alt (alt-convlstm), convlstm-cp-dy, convlstm-np-dy, convlstm-cp-y or convlstm-np-y",
            })
    }

    fn peephole(self) -> Peephole {
        match self {
            Self::Alt => Peephole::Accumulation,
            Self::CpDy | Self::CpY => Peephole::Cell,
            Self::NpDy | Self::NpY => Peephole::None,
        }
    }

    /// Whether the output cell's state is a position offset (the `-Y` baselines) rather
    /// than a velocity.
    pub(super) fn outputs_position(self) -> bool {
        matches!(self, Self::CpY | Self::NpY)
    }
}

/// The learnable weights of one cell (`c_in` → `c` channels).
#[derive(Debug, Clone)]
pub(super) struct Cell {
    pub(super) c: usize,
    pub(super) peephole: Peephole,
    /// `[c_in, 4c]` and `[c, 4c]`: the input and hidden convolutions of the gates i, f, c̃,
    /// o side by side.
    pub(super) w_x: Tensor,
    pub(super) w_h: Tensor,
    /// `[4c]`.
    pub(super) bias: Tensor,
    /// Peepholes: `[c, 2c]` for i and f (on the previous state), `[c, c]` for o (on the
    /// new one).
    pub(super) w_if: Option<Tensor>,
    pub(super) w_o: Option<Tensor>,
}

/// One cell's recurrent state, each `[B, V, c]`. `y` is Alt-ConvLSTM's accumulation;
/// `gates` the activated gates of the step that made it (none in the initial state), kept
/// for [`super::diagnose`].
#[derive(Debug, Clone)]
pub(super) struct CellState {
    h: Tensor,
    pub(super) c: Tensor,
    pub(super) y: Option<Tensor>,
    pub(super) gates: Option<Gates>,
}

/// The activated input, forget and output gates `i_t`, `f_t`, `o_t` of Eq. 5, each `[B, V, c]`.
#[derive(Debug, Clone)]
pub(super) struct Gates {
    pub(super) input: Tensor,
    pub(super) forget: Tensor,
    pub(super) output: Tensor,
}

impl Cell {
    /// A cell with Glorot-uniform weights scaled by `gain`.
    fn new(params: &mut ParamStore, name: &str, c_in: usize, c: usize, peephole: Peephole, gain: f64) -> Result<Self> {
        // Glorot-uniform over the gate block, as for the other sigmoid/tanh networks here.
        let glorot = |fan_in: usize, fan_out: usize| Init::Uniform(gain * (6.0 / (fan_in + fan_out) as f64).sqrt());
        let mut bias = vec![0.0f32; 4 * c];
        // The forget gate starts open (bias 1), the usual LSTM initialisation.
        bias[c..2 * c].fill(1.0);
        let bias_t = params.create(&format!("{name}.b"), &[4 * c], Init::Zeros)?;
        let cell = Self {
            c,
            peephole,
            w_x: params.create(&format!("{name}.wx"), &[c_in, 4 * c], glorot(c_in, c))?,
            w_h: params.create(&format!("{name}.wh"), &[c, 4 * c], glorot(c, c))?,
            bias: bias_t,
            w_if: match peephole {
                Peephole::None => None,
                _ => Some(params.create(&format!("{name}.wif"), &[c, 2 * c], glorot(c, c))?),
            },
            w_o: match peephole {
                Peephole::None => None,
                _ => Some(params.create(&format!("{name}.wo"), &[c, c], glorot(c, c))?),
            },
        };
        if let Some(var) = params.vars().get(&format!("{name}.b")) {
            var.set(&Tensor::from_vec(bias, 4 * c, params.device())?)?;
        }
        Ok(cell)
    }

    fn zero_state(&self, b: usize, v: usize, device: &Device) -> Result<CellState> {
        let z = Tensor::zeros((b, v, self.c), DType::F32, device)?;
        Ok(CellState {
            h: z.clone(),
            c: z.clone(),
            y: (self.peephole == Peephole::Accumulation).then_some(z),
            gates: None,
        })
    }

    /// One step of Eq. 5 (or the vanilla cell). `ax` is `Â_n X_t`; the accumulation adds
    /// `unit · C_t` (the state's unit in the accumulation's, 1 but for the output cell)
    /// and `skip` (Eq. 10, Eq. 11).
    fn step(
        &self,
        adj: &NormalizedAdjacency,
        ax: &Tensor,
        s: &CellState,
        skip: Option<&Tensor>,
        unit: f64,
    ) -> Result<CellState> {
        let c = self.c;
        let gates = (ax.broadcast_matmul(&self.w_x)? + adj.apply(&s.h)?.broadcast_matmul(&self.w_h)?)?
            .broadcast_add(&self.bias)?;
        let watched_before = match self.peephole {
            Peephole::Accumulation => s.y.as_ref(),
            Peephole::Cell => Some(&s.c),
            Peephole::None => None,
        };
        let (mut i, mut f) = (gates.narrow(2, 0, c)?, gates.narrow(2, c, c)?);
        if let (Some(w), Some(watched)) = (&self.w_if, watched_before) {
            let p = adj.apply(watched)?.broadcast_matmul(w)?;
            i = (i + p.narrow(2, 0, c)?)?;
            f = (f + p.narrow(2, c, c)?)?;
        }
        let i = candle_nn::ops::sigmoid(&i)?;
        let f = candle_nn::ops::sigmoid(&f)?;
        let candidate = gates.narrow(2, 2 * c, c)?.tanh()?;
        let cell = ((&f * &s.c)? + (&i * candidate)?)?;
        let y = match &s.y {
            Some(y) => {
                let mut y = if unit == 1.0 {
                    (y + &cell)?
                } else {
                    (y + (&cell * unit)?)?
                };
                if let Some(k) = skip {
                    y = (y + k)?;
                }
                Some(y)
            }
            None => None,
        };
        let mut o = gates.narrow(2, 3 * c, c)?;
        let watched_after = match self.peephole {
            Peephole::Accumulation => y.as_ref(),
            Peephole::Cell => Some(&cell),
            Peephole::None => None,
        };
        if let (Some(w), Some(watched)) = (&self.w_o, watched_after) {
            o = (o + adj.apply(watched)?.broadcast_matmul(w)?)?;
        }
        let o = candle_nn::ops::sigmoid(&o)?;
        let h = (&o * cell.tanh()?)?;
        Ok(CellState {
            h,
            c: cell,
            y,
            gates: Some(Gates {
                input: i,
                forget: f,
                output: o,
            }),
        })
    }
}

/// A whole model: five hidden cells and the output cell.
#[derive(Debug, Clone)]
pub struct AltConvNet {
    pub(super) variant: Variant,
    pub(super) cells: Vec<Cell>,
    /// Eq. 10's skips: `(layer, from)`, layer `layer`'s accumulation also adds `C^{from}`.
    pub(super) skips: Vec<(usize, usize)>,
    pub(super) scaling: Scaling,
}

/// The units the network works in: its 9 input channels standardised, and its output
/// state `C^out` measured in units of `output` metres (a velocity, or for the `-Y`
/// baselines an offset from the pose). [`Scaling::identity`] is the paper's raw metres.
///
/// A deviation from the paper, which states no normalisation: on the `limb` data a
/// vertex moves about a centimetre per frame and the tissue leaves the skin by about a
/// millimetre, while the output cell's candidate is bounded by 1 (tanh) in whatever unit
/// its state has. In metres, the first Adam steps moved the prediction by centimetres
/// (docs/ALTCONV.md). [`Scaling::fit`] measures both on the training split.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scaling {
    pub input_mean: [f64; INPUT_CHANNELS],
    pub input_std: [f64; INPUT_CHANNELS],
    pub output: f64,
}

impl Scaling {
    pub fn identity() -> Self {
        Self {
            input_mean: [0.0; INPUT_CHANNELS],
            input_std: [1.0; INPUT_CHANNELS],
            output: 1.0,
        }
    }
}

/// Skips of Eq. 10 between equal-width hidden cells, mirrored across the widest one.
fn mirrored_skips(hidden: &[usize]) -> Vec<(usize, usize)> {
    let n = hidden.len();
    (0..n / 2)
        .map(|k| (n - 1 - k, k))
        .filter(|&(l, k)| l > k + 1 && hidden[l] == hidden[k])
        .collect()
}

/// A sequence's driving inputs: the skinned surfaces `X_0..X_T` and the initial tissue
/// `Y_0`, as `[B, T + 1, V, 3]` and `[B, V, 3]` (metres).
#[derive(Debug, Clone)]
pub struct Drive {
    pub skinned: Tensor,
    pub initial: Tensor,
}

impl AltConvNet {
    /// A model with `hidden` cells (the paper's is [`HIDDEN`]) in `params`.
    pub fn new(params: &mut ParamStore, variant: Variant, hidden: &[usize]) -> Result<Self> {
        if hidden.is_empty() || hidden.contains(&0) {
            return Err(Error::InvalidParameter {
                name: "Alt-ConvLSTM hidden channels",
                value: format!("{hidden:?}"),
                reason: "needs at least one cell, each with at least one channel",
            });
        }
        let peephole = variant.peephole();
        let mut cells = Vec::with_capacity(hidden.len() + 1);
        let mut c_in = INPUT_CHANNELS;
        for (l, &c) in hidden.iter().enumerate() {
            cells.push(Cell::new(params, &format!("cell{l}"), c_in, c, peephole, 1.0)?);
            c_in = c;
        }
        // The output cell's state is in metres, and its candidate is bounded by 1 (tanh):
        // at full scale an untrained model moves vertices by up to a metre per step. Its
        // weights start at 1 % of the Glorot range, so training starts next to the skip
        // connections (Eq. 11: the previous surface moved with the pose).
        cells.push(Cell::new(params, "out", c_in, 3, peephole, OUTPUT_INIT_GAIN)?);
        let skips = if variant == Variant::Alt {
            mirrored_skips(hidden)
        } else {
            Vec::new()
        };
        Ok(Self {
            variant,
            cells,
            skips,
            scaling: Scaling::identity(),
        })
    }

    pub fn variant(&self) -> Variant {
        self.variant
    }

    /// The same network working in the units of `scaling`.
    pub fn with_scaling(mut self, scaling: Scaling) -> Self {
        self.scaling = scaling;
        self
    }

    pub fn scaling(&self) -> &Scaling {
        &self.scaling
    }

    /// Predicted surfaces `Ŷ_1..Ŷ_steps` (each `[B, V, 3]`). With `truth` (`[B, T + 1, V, 3]`)
    /// every step starts from the true previous surface (teacher forcing, single-step);
    /// without, from the model's own (roll-out).
    pub fn run(
        &self,
        adj: &NormalizedAdjacency,
        drive: &Drive,
        truth: Option<&Tensor>,
        steps: usize,
    ) -> Result<Vec<Tensor>> {
        self.run_forced(adj, drive, truth, steps, &|_| true)
    }

    /// [`AltConvNet::run`] with teacher forcing at step `t > 1` only where `forced(t)`:
    /// elsewhere the step starts from the model's own previous prediction, as a roll-out
    /// does (scheduled sampling, [`super::Recipe`]).
    pub fn run_forced(
        &self,
        adj: &NormalizedAdjacency,
        drive: &Drive,
        truth: Option<&Tensor>,
        steps: usize,
        forced: &dyn Fn(usize) -> bool,
    ) -> Result<Vec<Tensor>> {
        self.run_observed(adj, drive, truth, steps, forced, &mut |_, _| Ok(()))
    }

    /// [`AltConvNet::run_forced`], handing every layer's new state to `observe(t, states)`
    /// after step `t` (the diagnostics read the cells' gates and states from it).
    pub(super) fn run_observed(
        &self,
        adj: &NormalizedAdjacency,
        drive: &Drive,
        truth: Option<&Tensor>,
        steps: usize,
        forced: &dyn Fn(usize) -> bool,
        observe: &mut dyn FnMut(usize, &[CellState]) -> Result<()>,
    ) -> Result<Vec<Tensor>> {
        let (b, frames, v, three) = drive.skinned.dims4()?;
        if three != 3 || v != adj.num_vertices() || drive.initial.dims() != [b, v, 3] {
            return Err(Error::Shape {
                what: "Alt-ConvLSTM drive",
                expected: format!(
                    "skinned [B, T+1, {}, 3] and initial [B, {}, 3]",
                    adj.num_vertices(),
                    adj.num_vertices()
                ),
                got: format!("{:?} and {:?}", drive.skinned.dims(), drive.initial.dims()),
            });
        }
        if steps >= frames {
            return Err(Error::InvalidParameter {
                name: "Alt-ConvLSTM steps",
                value: steps.to_string(),
                reason: "needs one more skinned frame than steps",
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
        let device = drive.skinned.device();
        let x = |t: usize| -> Result<Tensor> { Ok(drive.skinned.narrow(1, t, 1)?.squeeze(1)?) };
        let y_true = |t: usize| -> Result<Option<Tensor>> {
            Ok(match truth {
                Some(tr) => Some(tr.narrow(1, t, 1)?.squeeze(1)?),
                None => None,
            })
        };
        let x0 = x(0)?;
        let offset0 = (&drive.initial - &x0)?;
        let unit = self.scaling.output;
        let mean = Tensor::from_vec(
            self.scaling.input_mean.map(|v| v as f32).to_vec(),
            INPUT_CHANNELS,
            device,
        )?;
        let inv_std = Tensor::from_vec(
            self.scaling.input_std.map(|v| (1.0 / v) as f32).to_vec(),
            INPUT_CHANNELS,
            device,
        )?;
        let mut states: Vec<CellState> = self
            .cells
            .iter()
            .map(|c| c.zero_state(b, v, device))
            .collect::<Result<_>>()?;
        // §5.1's initial state: the output accumulation is Y_0 (Alt-ConvLSTM); the -Y
        // baselines' output state is the initial offset from the pose.
        let out = self.cells.len() - 1;
        match self.variant {
            Variant::Alt => states[out].y = Some(drive.initial.clone()),
            v if v.outputs_position() => states[out].c = (&offset0 / unit)?,
            _ => {}
        }
        let mut previous = drive.initial.clone();
        let mut x_prev = x0;
        let mut predictions = Vec::with_capacity(steps);
        for t in 1..=steps {
            let xt = x(t)?;
            let dx = (&xt - &x_prev)?;
            if t > 1 && forced(t) {
                if let Some(y_prev) = y_true(t - 1)? {
                    // Teacher forcing: the step starts from the true surface.
                    match self.variant {
                        Variant::Alt => states[out].y = Some(y_prev.clone()),
                        v if v.outputs_position() => states[out].c = ((&y_prev - &x_prev)? / unit)?,
                        _ => {}
                    }
                    previous = y_prev;
                }
            }
            let input = Tensor::cat(&[&xt, &dx, &offset0], 2)?
                .broadcast_sub(&mean)?
                .broadcast_mul(&inv_std)?;
            let mut a_in = adj.apply(&input)?;
            let mut new_states: Vec<CellState> = Vec::with_capacity(self.cells.len());
            for (l, cell) in self.cells.iter().enumerate() {
                let skip = if l == out {
                    (self.variant == Variant::Alt).then_some(&dx)
                } else {
                    self.skips
                        .iter()
                        .find(|(to, _)| *to == l)
                        .map(|(_, from)| &new_states[*from].c)
                };
                let skip = skip.cloned();
                let s = cell.step(adj, &a_in, &states[l], skip.as_ref(), if l == out { unit } else { 1.0 })?;
                if l < out {
                    a_in = adj.apply(&s.c)?;
                }
                new_states.push(s);
            }
            states = new_states;
            observe(t, &states)?;
            let prediction = match self.variant {
                Variant::Alt => states[out]
                    .y
                    .clone()
                    .unwrap_or_else(|| unreachable!("Alt-ConvLSTM accumulates")),
                v if v.outputs_position() => (&xt + (&states[out].c * unit)?)?,
                _ => ((&previous + (&states[out].c * unit)?)? + &dx)?,
            };
            previous = prediction.clone();
            predictions.push(prediction);
            x_prev = xt;
        }
        Ok(predictions)
    }
}
