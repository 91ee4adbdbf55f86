//! The altconv experiment's scoring: a model's (or skinning's) single-step and roll-out
//! errors on a set of sequences, the statistics the tables read from them, the
//! predictions written beside the ground truth, and [`score_model`] for a model trained
//! outside the evaluation.

use std::collections::HashMap;

use weft_data::{LimbDataset, LimbSequence};
use weft_nn::altconv::{AltConvNet, score_sequence};
use weft_nn::graph::NormalizedAdjacency;

use super::linear_filter::LinearFilter;
use super::{SKINNING, WINDOWS};
use crate::error::Context;
use crate::evaluate::context::{EvalContext, Scoring};
use crate::records::{ExperimentOutput, Timing, mean_sd};

/// Per-step pooled vertex errors (mm) of one method on one split: `[step][sample]`.
pub(super) struct Errors {
    pub single: Vec<Vec<f64>>,
    pub rollout: Vec<Vec<f64>>,
    /// Roll-out wall time per step and sequence (s).
    pub seconds_per_frame: f64,
    /// The last roll-out step's vertex errors (m) and surface of the split's first
    /// sequence, for the heat map.
    pub last: Option<(Vec<f64>, Vec<f64>)>,
    /// Every sequence's roll-out surfaces, flattened `[steps, V, 3]` each.
    pub surfaces: Vec<Vec<f64>>,
}

/// The `q` quantile of `samples` (nearest rank).
pub(super) fn percentile(samples: &[f64], q: f64) -> f64 {
    let mut v = samples.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(((q * v.len() as f64).ceil() as usize).saturating_sub(1))
        .copied()
        .unwrap_or(0.0)
}

/// Steps 1..=n pooled.
pub(super) fn window(steps: &[Vec<f64>], n: usize) -> (f64, f64) {
    mean_sd(steps[..n].iter().flatten().copied())
}

/// The per-vertex Euclidean distances between two flat `3V` surfaces (their units).
pub(super) fn vertex_distances<'a>(a: &'a [f64], b: &'a [f64]) -> impl Iterator<Item = f64> + 'a {
    a.chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
}

/// The mean per-vertex distance (mm) between two sets of roll-outs (each sequence's
/// surfaces flattened `[steps, V, 3]`, metres).
pub(super) fn mean_distance_mm(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    mean_sd(
        a.iter()
            .zip(b)
            .flat_map(|(a, b)| vertex_distances(a, b).map(|d| 1e3 * d)),
    )
    .0
}

/// What predicts a surface: the skinning row, a trained network or the linear filter.
#[derive(Clone, Copy)]
pub(super) enum Predictor<'a> {
    Skinning,
    Net(&'a AltConvNet),
    Filter(&'a LinearFilter),
}

/// The largest per-vertex error over the first `n` steps (mm).
pub(super) fn peak(steps: &[Vec<f64>], n: usize) -> f64 {
    steps[..n].iter().flatten().copied().fold(0.0, f64::max)
}

/// Scores `predictor` on `sequences` over `horizon` steps.
pub(super) fn score(
    predictor: Predictor,
    adj: &NormalizedAdjacency,
    sequences: &[&LimbSequence],
    horizon: usize,
) -> crate::Result<Errors> {
    let mut single = vec![Vec::new(); horizon];
    let mut rollout = vec![Vec::new(); horizon];
    let mut seconds = 0.0;
    let mut last = None;
    let mut surfaces = Vec::with_capacity(sequences.len());
    for (k, s) in sequences.iter().enumerate() {
        let e = match predictor {
            Predictor::Skinning => score_sequence(None, adj, s, horizon)?,
            Predictor::Net(net) => score_sequence(Some(net), adj, s, horizon)?,
            Predictor::Filter(filter) => filter.score_sequence(s, horizon),
        };
        seconds += e.rollout_seconds;
        for t in 0..horizon {
            single[t].extend(e.single[t].iter().map(|e| 1e3 * e));
            rollout[t].extend(e.rollout[t].iter().map(|e| 1e3 * e));
        }
        if k == 0 {
            last = Some((e.rollout[horizon - 1].clone(), e.rollout_surfaces[horizon - 1].clone()));
        }
        surfaces.push(e.rollout_surfaces.concat());
    }
    Ok(Errors {
        single,
        rollout,
        seconds_per_frame: seconds / (horizon * sequences.len().max(1)) as f64,
        last,
        surfaces,
    })
}

/// Writes `predictions/altconv/limb/<method>.safetensors`: the roll-outs of the `source`
/// split's sequences beside their ground truth, steps 1..=`horizon`.
pub(super) fn write_predictions(
    ctx: &EvalContext,
    method: &str,
    dataset: &LimbDataset,
    source: &str,
    horizon: usize,
    surfaces: &[Vec<f64>],
) -> crate::Result<()> {
    let dir = ctx.out.join("predictions").join("altconv").join(&dataset.name);
    std::fs::create_dir_all(&dir)?;
    let sequences: Vec<_> = dataset.split(source).collect();
    let truth: Vec<f64> = sequences
        .iter()
        .flat_map(|s| s.simulated[1..=horizon].iter().flatten().copied())
        .collect();
    let index: Vec<i64> = sequences.iter().map(|s| s.index as i64).collect();
    let shape = vec![sequences.len(), horizon, dataset.rest.num_vertices(), 3];
    let mut meta = HashMap::new();
    meta.insert(
        "units".into(),
        format!(
            "positions (the roll-out from each sequence's initial surface) and ground_truth [sequences, steps 1..={horizon}, \
             vertices, 3] in metres, the `{source}` sequences of the limb dataset; sequence_index [sequences]"
        ),
    );
    Ok(weft_data::files::write_safetensors(
        &dir.join(format!("{method}.safetensors")),
        &[
            weft_data::files::Array::f64("positions", shape.clone(), &surfaces.concat()),
            weft_data::files::Array::f64("ground_truth", shape, &truth),
            weft_data::files::Array::i64("sequence_index", &index),
        ],
        meta,
    )?)
}

/// Scores the model in `model_dir` (`cargo xtask train altconv`) on the `split` sequences
/// of the `limb` dataset in `data_dir`, beside skinning alone, with the evaluation's
/// metrics: `error-mm-step1` and `error-mm-rollout{10,…,50}` (windows up to the shortest
/// sequence), and each method's predictions under `ctx.out/predictions/altconv/limb/`.
pub fn score_model(scoring: &Scoring) -> crate::Result<ExperimentOutput> {
    let (ctx, data_dir, split) = (scoring.ctx, scoring.data_dir, scoring.split);
    let dataset = LimbDataset::load(data_dir)?;
    let (config, _, net) = scoring.load_model(|dir| weft_nn::altconv::load_model(dir, &weft_nn::Device::Cpu))?;
    let adj = NormalizedAdjacency::new(&dataset.rest)?;
    let sequences: Vec<&LimbSequence> = dataset.split(split).collect();
    scoring.require(sequences.len(), "sequence")?;
    let horizon = sequences
        .iter()
        .map(|s| s.skinned.len() - 1)
        .min()
        .unwrap_or(0)
        .min(*WINDOWS.last().unwrap_or(&50));
    crate::error::ensure!(horizon >= 1, "the {split} sequences hold no step");
    let gt = scoring.ground_truth_seconds();
    let mut out = scoring.output(format_args!(
        "on the {split} sequences of {} ({} of them, steps 1–{horizon}), beside skinning",
        data_dir.display(),
        sequences.len()
    ));
    for (method, model) in [
        (SKINNING, Predictor::Skinning),
        (config.variant.name(), Predictor::Net(&net)),
    ] {
        let e = score(model, &adj, &sequences, horizon).with_context(|| format!("scoring {method}"))?;
        let timing = Timing {
            seconds_per_frame: Some(e.seconds_per_frame),
            ground_truth_seconds_per_frame: gt,
        };
        out.record(
            &dataset.name,
            method,
            "error-mm-step1",
            window(&e.single, horizon).0,
            "mm",
            timing,
        );
        out.split(split);
        for w in WINDOWS.into_iter().filter(|&w| w <= horizon) {
            out.record(
                &dataset.name,
                method,
                &format!("error-mm-rollout{w}"),
                window(&e.rollout, w).0,
                "mm",
                timing,
            );
            out.split(split);
        }
        out.record(
            &dataset.name,
            method,
            &format!("error-mm-max-rollout{horizon}"),
            peak(&e.rollout, horizon),
            "mm",
            timing,
        );
        out.split(split);
        write_predictions(ctx, method, &dataset, split, horizon, &e.surfaces)?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_distance_to_skinning_is_the_mean_vertex_distance() {
        // Two sequences, one step of two vertices each: distances 1, 0 and 3, 4 (m).
        let a = vec![vec![1.0, 0.0, 0.0, 5.0, 5.0, 5.0], vec![0.0, 3.0, 0.0, 0.0, 0.0, 4.0]];
        let b = vec![vec![0.0; 3].into_iter().chain([5.0; 3]).collect(), vec![0.0; 6]];
        assert!((mean_distance_mm(&a, &b) - 1e3 * 8.0 / 4.0).abs() < 1e-9);
        assert_eq!(mean_distance_mm(&b, &b), 0.0);
    }

    #[test]
    fn windows_pool_every_sample_of_their_steps() {
        let steps = vec![vec![1.0, 3.0], vec![5.0, 7.0], vec![100.0]];
        assert_eq!(window(&steps, 2), (4.0, 5.0f64.sqrt()));
        let (m, _) = window(&steps, 3);
        assert!((m - 23.2).abs() < 1e-12);
        let hundred: Vec<f64> = (1..=100).map(f64::from).rev().collect();
        assert_eq!(percentile(&hundred, 0.99), 99.0);
        assert_eq!(percentile(&hundred, 0.5), 50.0);
        assert_eq!(percentile(&[], 0.5), 0.0);
    }
}
