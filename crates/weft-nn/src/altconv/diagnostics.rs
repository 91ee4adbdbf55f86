//! What a trained model's cells do over a roll-out (issue 69's saturation trap): per step
//! and layer, the activated gates of Eq. 5 (their mean and the share of entries below
//! [`SHUT_GATE`], a gate that passes under 2 % and so sends back under 2 % of the
//! gradient), the mean |C^l| of the cell states and the mean |Y^l| of Alt-ConvLSTM's
//! accumulations `Y^l = ΣC^l`; and per layer the RMS of the roll-out loss's gradient
//! before clipping, the gradient the optimiser receives.
//!
//! The gates and states are read from the autograd model's own forward pass
//! ([`AltConvNet::run_forced`], through an observer), not re-derived here: the figures are
//! those of the equations the model trains with. The forward pass runs on detached weights
//! (no tape is kept over 50 steps). The gradients come from the fused op, the training
//! path (tested equal to autograd), on one sequence at a time, as training takes its Adam
//! steps (one sequence per step, clipped to a global norm after this measurement).
//!
//! The network computes in f32; every statistic is accumulated and reported in f64.

use std::path::Path;

use candle_core::{DType, Device, Tensor};
use serde::{Deserialize, Serialize};

use super::model::{AltConvNet, CellState};
use super::{FusedWorkspace, SequenceTensors, load_model, mean_vertex_error_stacked};
use crate::error::{Error, Result};
use crate::graph::NormalizedAdjacency;
use crate::params::ParamStore;

/// A gate entry below this passes (and sends back) under 2 % of its signal: "shut".
pub const SHUT_GATE: f64 = 0.02;
/// The roll-out steps [`DiagnosticsReport::table`] prints.
pub const TABLE_STEPS: [usize; 5] = [1, 5, 10, 25, 50];

/// One gate's entries at one step of one layer, over every vertex, channel and sequence.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GateStats {
    pub mean: f64,
    /// The share of entries below [`SHUT_GATE`] (0–1).
    pub shut: f64,
}

/// One layer at one roll-out step, averaged over the sequences.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayerStep {
    /// `i_t`, `f_t` and `o_t` of Eq. 5.
    pub input_gate: GateStats,
    pub forget_gate: GateStats,
    pub output_gate: GateStats,
    /// Mean |C_t^l| in the cell's own units (the output cell's: [`super::Scaling::output`]
    /// metres).
    pub cell_abs_mean: f64,
    /// Mean |Y_t^l| (Alt-ConvLSTM only; the output cell's is the predicted surface, in
    /// metres from the origin).
    pub accumulation_abs_mean: Option<f64>,
}

/// One roll-out step: its error and every layer's statistics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepDiagnostics {
    /// 1-based.
    pub step: usize,
    /// Eq. 12 at this step of the roll-out, mean over vertices and sequences (mm).
    pub rollout_error_mm: f64,
    /// In [`DiagnosticsReport::layers`] order.
    pub layers: Vec<LayerStep>,
}

/// One layer's gradient of the roll-out loss (Eq. 12 over all steps) before clipping.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayerGradient {
    pub layer: String,
    pub parameters: usize,
    /// `√(mean over sequences of Σg²/parameters)`.
    pub rms: f64,
}

/// [`diagnose`]'s result, written as JSON by `cargo xtask altconv-diagnostics`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiagnosticsReport {
    pub variant: String,
    /// The split (or other source) the sequences came from.
    pub split: String,
    pub sequences: usize,
    pub steps: usize,
    /// The cells bottom to top, by their parameters' prefix: `cell0`…, then `out`.
    pub layers: Vec<String>,
    pub gradients: Vec<LayerGradient>,
    /// The global gradient norm per sequence, mean over sequences: what the training's
    /// clipping (to norm 1 on `limb-jiggle`) compares.
    pub gradient_norm: f64,
    pub per_step: Vec<StepDiagnostics>,
}

/// Sums of one layer's statistics over sequences, at one step.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    gates: [[f64; 2]; 3],
    cell: f64,
    accumulation: Option<f64>,
}

/// Mean of `|x|` (or of `x`) and the share of entries below [`SHUT_GATE`], in f64.
fn moments(t: &Tensor) -> Result<(f64, f64, f64)> {
    let v = t.flatten_all()?.to_dtype(DType::F32)?.to_vec1::<f32>()?;
    let n = v.len().max(1) as f64;
    let (mut sum, mut abs, mut shut) = (0.0, 0.0, 0usize);
    for &x in &v {
        let x = f64::from(x);
        sum += x;
        abs += x.abs();
        shut += usize::from(x < SHUT_GATE);
    }
    Ok((sum / n, abs / n, shut as f64 / n))
}

impl AltConvNet {
    /// The same network with its weights detached from the parameter store: its forward
    /// pass records no tape.
    fn detached(&self) -> Self {
        let mut net = self.clone();
        for cell in &mut net.cells {
            cell.w_x = cell.w_x.detach();
            cell.w_h = cell.w_h.detach();
            cell.bias = cell.bias.detach();
            cell.w_if = cell.w_if.as_ref().map(Tensor::detach);
            cell.w_o = cell.w_o.as_ref().map(Tensor::detach);
        }
        net
    }

    /// The layers' names, bottom to top (their parameters' prefixes).
    fn layer_names(&self) -> Vec<String> {
        let out = self.cells.len() - 1;
        (0..=out)
            .map(|l| {
                if l == out {
                    "out".to_string()
                } else {
                    format!("cell{l}")
                }
            })
            .collect()
    }
}

/// Adds one step's layer states to `sums`.
fn observe(sums: &mut [Sums], states: &[CellState]) -> Result<()> {
    for (s, state) in sums.iter_mut().zip(states) {
        let gates = state
            .gates
            .as_ref()
            .unwrap_or_else(|| unreachable!("a stepped cell has gates"));
        for (k, g) in [&gates.input, &gates.forget, &gates.output].into_iter().enumerate() {
            let (mean, _, shut) = moments(g)?;
            s.gates[k][0] += mean;
            s.gates[k][1] += shut;
        }
        s.cell += moments(&state.c)?.1;
        if let Some(y) = &state.y {
            *s.accumulation.get_or_insert(0.0) += moments(y)?.1;
        }
    }
    Ok(())
}

/// The roll-out's per-step statistics, summed over `sequences` (rolled out from their
/// first frame on detached weights), and the per-step errors summed (m).
fn rollout_sums(
    net: &AltConvNet,
    adj: &NormalizedAdjacency,
    sequences: &[SequenceTensors],
    steps: usize,
) -> Result<(Vec<Vec<Sums>>, Vec<f64>)> {
    let detached = net.detached();
    let mut sums = vec![vec![Sums::default(); net.cells.len()]; steps];
    let mut errors = vec![0.0; steps];
    for s in sequences {
        let predictions = detached.run_observed(adj, &s.drive, None, steps, &|_| false, &mut |t, states| {
            observe(&mut sums[t - 1], states)
        })?;
        for (k, p) in predictions.iter().enumerate() {
            let truth = s.truth.narrow(1, k + 1, 1)?.squeeze(1)?;
            let d = (p - truth)?.sqr()?.sum(2)?.sqrt()?.to_dtype(DType::F64)?;
            errors[k] += d.mean_all()?.to_scalar::<f64>()?;
        }
    }
    Ok((sums, errors))
}

/// Per layer, the sum over sequences of `Σg²` of the roll-out loss's gradient, and the
/// sum over sequences of the global norm.
fn gradient_sums(
    net: &AltConvNet,
    params: &ParamStore,
    adj: &NormalizedAdjacency,
    sequences: &[SequenceTensors],
    steps: usize,
    layers: &[String],
) -> Result<(Vec<f64>, f64)> {
    let workspace = FusedWorkspace::new();
    let forced = vec![false; steps + 1];
    let mut per_layer = vec![0.0; layers.len()];
    let mut norm = 0.0;
    for s in sequences {
        let predicted = net.run_fused(adj, &s.drive, Some(&s.truth), steps, &forced, &workspace)?;
        let grads = mean_vertex_error_stacked(&predicted, &s.truth)?.backward()?;
        let mut total = 0.0;
        for (name, var) in params.vars() {
            let prefix = name.split('.').next().unwrap_or_default();
            let Some(l) = layers.iter().position(|n| n == prefix) else {
                continue;
            };
            let sq = match grads.get(var.as_tensor()) {
                Some(g) => g.to_dtype(DType::F64)?.sqr()?.sum_all()?.to_scalar::<f64>()?,
                None => 0.0,
            };
            per_layer[l] += sq;
            total += sq;
        }
        norm += total.sqrt();
    }
    Ok((per_layer, norm))
}

/// The diagnostics of `net` (its weights in `params`) rolled out over `steps` steps of
/// each of `sequences` (each holding at least `steps + 1` frames) on the mesh `adj`.
pub fn diagnose(
    net: &AltConvNet,
    params: &ParamStore,
    adj: &NormalizedAdjacency,
    sequences: &[SequenceTensors],
    steps: usize,
    split: &str,
) -> Result<DiagnosticsReport> {
    if sequences.is_empty() || steps == 0 {
        return Err(Error::InvalidParameter {
            name: "diagnosed sequences and steps",
            value: format!("{} sequences, {steps} steps", sequences.len()),
            reason: "needs at least one sequence and one step",
        });
    }
    let layers = net.layer_names();
    let (sums, errors) = rollout_sums(net, adj, sequences, steps)?;
    let n = sequences.len() as f64;
    let per_step = sums
        .iter()
        .zip(&errors)
        .enumerate()
        .map(|(k, (layer_sums, e))| StepDiagnostics {
            step: k + 1,
            rollout_error_mm: 1e3 * e / n,
            layers: layer_sums
                .iter()
                .map(|s| {
                    let gate = |g: usize| GateStats {
                        mean: s.gates[g][0] / n,
                        shut: s.gates[g][1] / n,
                    };
                    LayerStep {
                        input_gate: gate(0),
                        forget_gate: gate(1),
                        output_gate: gate(2),
                        cell_abs_mean: s.cell / n,
                        accumulation_abs_mean: s.accumulation.map(|a| a / n),
                    }
                })
                .collect(),
        })
        .collect();
    let (per_layer, norm) = gradient_sums(net, params, adj, sequences, steps, &layers)?;
    let mut counts = vec![0usize; layers.len()];
    for (name, var) in params.vars() {
        if let Some(l) = layers.iter().position(|n| Some(n.as_str()) == name.split('.').next()) {
            counts[l] += var.elem_count();
        }
    }
    let gradients = layers
        .iter()
        .zip(&per_layer)
        .zip(&counts)
        .map(|((layer, &sq), &count)| LayerGradient {
            layer: layer.clone(),
            parameters: count,
            rms: (sq / n / count.max(1) as f64).sqrt(),
        })
        .collect();
    Ok(DiagnosticsReport {
        variant: net.variant().name().to_string(),
        split: split.to_string(),
        sequences: sequences.len(),
        steps,
        layers,
        gradients,
        gradient_norm: norm / n,
        per_step,
    })
}

/// [`diagnose`] for a model directory (`cargo xtask train altconv`, at its best weights)
/// on the `split` sequences of a `limb` dataset directory, over `steps` steps or the
/// shortest sequence's, whichever is fewer.
pub fn diagnose_model(model: &Path, data: &Path, split: &str, steps: usize) -> Result<DiagnosticsReport> {
    let device = Device::Cpu;
    let (_, params, net) = load_model(model, &device)?;
    let dataset = weft_data::LimbDataset::load(data)?;
    let adj = NormalizedAdjacency::new(&dataset.rest)?;
    let chosen: Vec<_> = dataset.split(split).collect();
    let frames = chosen.iter().map(|s| s.skinned.len()).min().unwrap_or(0);
    if frames < 2 {
        return Err(Error::InvalidParameter {
            name: "diagnosed split",
            value: split.to_string(),
            reason: "holds no sequence of two frames or more in this dataset",
        });
    }
    let steps = steps.min(frames - 1);
    let sequences = chosen
        .iter()
        .map(|s| SequenceTensors::new(s, steps + 1, &device))
        .collect::<Result<Vec<_>>>()?;
    diagnose(&net, &params, &adj, &sequences, steps, split)
}

impl DiagnosticsReport {
    /// Writes the report as pretty JSON to `path`.
    pub fn write(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self).expect("plain data");
        Ok(weft_data::files::write_text(path, &text)?)
    }

    /// A short text summary: per layer, at the [`TABLE_STEPS`] within the roll-out, the
    /// input and output gates' means and shut shares, mean |C| and mean |Y|; then each
    /// layer's gradient RMS and the roll-out error at those steps.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{} on {} sequences ({}), {} steps; gates: mean / share < {SHUT_GATE}\n{:<6} {:>4} {:>14} {:>14} {:>10} {:>10}\n",
            self.variant,
            self.sequences,
            self.split,
            self.steps,
            "layer",
            "step",
            "input gate",
            "output gate",
            "mean |C|",
            "mean |Y|"
        );
        let steps: Vec<&StepDiagnostics> = TABLE_STEPS
            .iter()
            .filter_map(|&t| self.per_step.get(t.wrapping_sub(1)))
            .collect();
        for (l, layer) in self.layers.iter().enumerate() {
            for d in &steps {
                let x = &d.layers[l];
                let gate = |g: &GateStats| format!("{:.3} / {:>4.0}%", g.mean, 100.0 * g.shut);
                let y = x.accumulation_abs_mean.map_or("-".to_string(), |y| format!("{y:.3e}"));
                s += &format!(
                    "{layer:<6} {:>4} {:>14} {:>14} {:>10.3e} {y:>10}\n",
                    d.step,
                    gate(&x.input_gate),
                    gate(&x.output_gate),
                    x.cell_abs_mean
                );
            }
        }
        s += "gradient RMS before clipping (roll-out loss, per sequence):";
        for g in &self.gradients {
            s += &format!(" {} {:.3e};", g.layer, g.rms);
        }
        s += &format!(" global norm {:.3e}\nroll-out error (mm):", self.gradient_norm);
        for d in &steps {
            s += &format!(" step {} {:.3};", d.step, d.rollout_error_mm);
        }
        s.pop();
        s.push('\n');
        s
    }
}
