//! What the experiments share: their [`EvalContext`] and the datasets they generate (or
//! complete) under the evaluation's directory, with the ground truth's cost per frame.

use std::path::{Path, PathBuf};

use weft_data::Size;

use crate::error::Context;

/// What every experiment of a run shares: the size, where it writes, whether it shows
/// progress, and the code version its datasets' manifests record.
#[derive(Debug, Clone)]
pub struct EvalContext {
    pub size: Size,
    /// The evaluation's output directory; an experiment writes under `out/<name>/`.
    pub out: PathBuf,
    pub quiet: bool,
    pub code_version: String,
}

/// Generates `scene`'s dataset into `dir`, or completes one an interrupted run left there
/// (the generator rewrites its manifest after every sequence, so a manifest alone does
/// not mean the dataset is whole). Returns the sequences that stopped early — a solve
/// that did not converge; their frames up to it are stored and used — for the
/// experiment's failures, on every run that reads the dataset.
pub fn generate_dataset(ctx: &EvalContext, scene: &str, dir: &Path) -> crate::Result<Vec<String>> {
    generate_dataset_frames(ctx, scene, dir, None)
}

/// [`generate_dataset`] with the size's frames per sequence overridden.
pub fn generate_dataset_frames(
    ctx: &EvalContext,
    scene: &str,
    dir: &Path,
    frames: Option<usize>,
) -> crate::Result<Vec<String>> {
    let manifest = dir.join("manifest.json");
    let exists = manifest.exists();
    if exists {
        let m = weft_data::read_manifest(&manifest)?;
        if m.is_complete() {
            return Ok(stopped_early(scene, &m));
        }
    }
    let mut spec = weft_data::DatasetSpec::new(scene, ctx.size)?;
    if let Some(f) = frames {
        spec.frames = f;
    }
    let options = weft_data::GenerateOptions {
        resume: exists,
        quiet: true,
        code_version: ctx.code_version.clone(),
        ..Default::default()
    };
    // Sequences that stopped early are stored up to the failure: the experiment uses them
    // and reports which.
    Ok(stopped_early(scene, &weft_data::generate(&spec, dir, &options)?))
}

fn stopped_early(scene: &str, m: &weft_data::Manifest) -> Vec<String> {
    m.stopped_early()
        .into_iter()
        .map(|l| format!("{scene} dataset: {l}"))
        .collect()
}

/// Ground-truth solver seconds per frame of a dataset (its `timing.json`).
pub fn ground_truth_seconds(dir: &Path) -> crate::Result<f64> {
    let t: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("timing.json"))?)?;
    let (mut frames, mut seconds) = (0.0, 0.0);
    for v in t["sequences"]
        .as_object()
        .context("timing.json lists no sequences")?
        .values()
    {
        frames += v[0].as_f64().unwrap_or(0.0);
        seconds += v[1].as_f64().unwrap_or(0.0);
    }
    crate::error::ensure!(frames > 0.0, "timing.json counts no frames");
    Ok(seconds / frames)
}
