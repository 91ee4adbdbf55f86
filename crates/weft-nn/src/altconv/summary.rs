//! What `cargo xtask train altconv` reports of a model it trained: its roll-out error over
//! up to 50 steps of the dataset's validation sequences beside skinning alone, written to
//! `scores.json` in the model directory and returned for printing. Validation, not test:
//! a run made to choose a recipe must not see the figures the claim is decided on (the
//! evaluation reads the test split once).
//!
//! What is not here: the evaluation's test-split scores and tables (weft-experiments').

use std::path::Path;

use crate::altconv::{TrainedAltConv, score_sequence};
use crate::error::Result;

/// The longest roll-out scored (steps).
pub const HORIZON: usize = 50;

/// Mean roll-out errors over the validation sequences.
#[derive(Debug, Clone, PartialEq)]
pub struct RolloutSummary {
    /// Steps rolled out: the shortest validation sequence's, at most [`HORIZON`].
    pub steps: usize,
    /// Per model (`skinning`, then the trained variant's name), the mean per-vertex
    /// roll-out error over steps `1..=steps` of every validation sequence (mm).
    pub errors_mm: Vec<(String, f64)>,
}

/// Scores `trained` and skinning alone on `dataset`'s validation sequences and writes
/// `scores.json` (`{"steps", "validation_rollout_mm": {name: mm}}`) into `out`; `None`
/// (and nothing written) when the dataset has no validation sequence.
pub fn validation_rollout(
    out: &Path,
    dataset: &weft_data::LimbDataset,
    trained: &TrainedAltConv,
) -> Result<Option<RolloutSummary>> {
    let validation: Vec<_> = dataset.split("validation").collect();
    let Some(frames) = validation.iter().map(|s| s.skinned.len()).min() else {
        return Ok(None);
    };
    let steps = (frames - 1).min(HORIZON);
    let mut errors_mm = Vec::new();
    for (name, model) in [("skinning", None), (trained.net.variant().name(), Some(&trained.net))] {
        let mut sum = (0.0, 0usize);
        for s in &validation {
            let e = score_sequence(model, &trained.adj, s, steps)?;
            sum.0 += e.rollout.iter().flatten().sum::<f64>();
            sum.1 += e.rollout.iter().map(Vec::len).sum::<usize>();
        }
        errors_mm.push((name.to_string(), 1e3 * sum.0 / sum.1.max(1) as f64));
    }
    let scores: serde_json::Map<String, serde_json::Value> = errors_mm
        .iter()
        .map(|(name, mm)| (name.clone(), serde_json::json!(mm)))
        .collect();
    let text = serde_json::to_string_pretty(&serde_json::json!({ "steps": steps, "validation_rollout_mm": scores }))
        .expect("plain data");
    weft_data::files::write_text(&out.join("scores.json"), &text)?;
    Ok(Some(RolloutSummary { steps, errors_mm }))
}
