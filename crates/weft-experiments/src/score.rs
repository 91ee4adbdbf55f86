//! Scoring a trained model on any dataset of its kind — another seed, another size, data it
//! never saw — without retraining, in the evaluation's metrics and file formats.
//!
//! [`score`] reads a model directory written by `cargo xtask train` (or by the evaluation)
//! and a dataset directory written by `cargo xtask dataset`, scores the model on one split
//! with the same functions the evaluation uses, and writes `results.json` (tidy records,
//! docs/RESULTS.md) and `predictions/<experiment>/<scene>/<method>.safetensors` into the
//! output directory.

use std::path::PathBuf;

use crate::error::Context;
use crate::evaluate::context::{EvalContext, Scoring};
use crate::evaluate::{altconv, drape, embed, nnwarp};
use crate::records::ExperimentOutput;

/// The kinds of trained model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelKind {
    /// Tan et al.'s embedding (`train embed`), on a cloth dataset's test frames.
    Embed,
    /// NNWarp's MLP (`train nnwarp`), on an `nnwarp` dataset.
    Nnwarp,
    /// Alt-ConvLSTM or a ConvLSTM baseline (`train altconv`), on a `limb` dataset.
    Altconv,
    /// A drape model (`train drape`), on a `drape` dataset.
    Drape,
}

impl ModelKind {
    pub const ALL: [ModelKind; 4] = [Self::Embed, Self::Nnwarp, Self::Altconv, Self::Drape];

    /// The experiment name of its records.
    pub fn name(self) -> &'static str {
        match self {
            Self::Embed => "embed",
            Self::Nnwarp => "nnwarp",
            Self::Altconv => "altconv",
            Self::Drape => "drape",
        }
    }
}

impl std::str::FromStr for ModelKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| format!("{s:?} is not a model kind (embed, nnwarp, altconv or drape)"))
    }
}

/// What to score, on what, and where the results go.
#[derive(Debug, Clone)]
pub struct ScoreOptions {
    pub kind: ModelKind,
    /// The model directory.
    pub model: PathBuf,
    /// The dataset directory.
    pub data: PathBuf,
    /// `train`, `validation` or `test` (embed: `test`, Tan et al.'s test frames, or
    /// `validation`, the windows the evaluation chooses on).
    pub split: String,
    /// Where `results.json` and `predictions/` are written.
    pub out: PathBuf,
}

/// Scores the model on the split, writes `results.json` and the predictions into
/// `options.out`, and returns the output (its records, notes and failures).
pub fn score(options: &ScoreOptions) -> crate::Result<ExperimentOutput> {
    if !["train", "validation", "test"].contains(&options.split.as_str()) {
        return Err(crate::Error::Invalid(format!(
            "split {:?}: splits are train, validation and test",
            options.split
        )));
    }
    let manifest = weft_data::read_manifest(&options.data.join("manifest.json"))?;
    std::fs::create_dir_all(&options.out)
        .with_context(|| format!("creating the output directory {}", options.out.display()))?;
    let ctx = EvalContext {
        size: manifest.size,
        out: options.out.clone(),
        quiet: true,
        code_version: manifest.code_version.clone(),
        jobs: 1,
    };
    let scoring = Scoring {
        ctx: &ctx,
        experiment: options.kind.name(),
        model_dir: &options.model,
        data_dir: &options.data,
        split: &options.split,
    };
    let output = match options.kind {
        ModelKind::Embed => embed::score_model(&scoring)?,
        ModelKind::Nnwarp => nnwarp::score_model(&scoring)?,
        ModelKind::Altconv => altconv::score_model(&scoring)?,
        ModelKind::Drape => drape::score_model(&scoring)?,
    };
    crate::records::validate(&output.records)?;
    weft_data::files::write_json(&options.out.join("results.json"), &output.records)?;
    Ok(output)
}
