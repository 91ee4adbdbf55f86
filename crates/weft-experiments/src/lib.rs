//! weft's experiments as a library: each paper's protocol run end to end, trained models
//! scored on any dataset of their kind, and a report a newcomer reads first.
//!
//! What is here:
//! - [`evaluate`]: the six experiments — `sim` (ground-truth solvers against tight
//!   references), `proj` (the projection layers), `embed` (Tan et al.), `nnwarp` (Luo et
//!   al.), `altconv` (Alt-ConvLSTM), `drape` (Geng et al.) — each generating its datasets
//!   (weft-data), training its models (weft-nn's one trainer) and timing every method
//!   beside the ground truth in the same run; outputs are cached per experiment so an
//!   evaluation resumes;
//! - [`records`]: tidy records (the rows of `results.json`), curves, energies, scatters;
//!   [`paper`]: the papers' tables beside ours;
//! - [`report`]: `results.json`, `tables.md`, plots, renders and one self-contained
//!   `index.html`, rebuilt from every cached experiment, and [`report::check`];
//! - [`score`]: any trained model scored on any dataset of its kind, in the evaluation's
//!   records and prediction files;
//! - [`render`]: per-vertex error images; [`stability`]: the stability map;
//! - [`progress`]: a training run's progress bar and epoch lines;
//! - [`files`]: the file helpers every module may use (the bottom layer; a test checks
//!   that no module imports from a layer above its own).
//!
//! What is not here: no physics, features, projections or networks of its own (weft-sim,
//! weft-acap, weft-proj, weft-nn), no dataset format (weft-data), no command line (xtask
//! parses arguments into [`evaluate::EvaluateOptions`] and the like).
//!
//! A quick dataset, a model trained on it, scored on a dataset of another seed:
//!
//! ```no_run
//! use weft_data::{DatasetSpec, GenerateOptions, LimbDataset, Size, generate};
//! use weft_experiments::score::{ModelKind, ScoreOptions, score};
//! let spec = DatasetSpec::new("limb", Size::Quick)?;
//! generate(&spec, "data/limb".as_ref(), &GenerateOptions::default())?;
//! let other = GenerateOptions { seed: 1, ..GenerateOptions::default() };
//! generate(&spec, "data/limb-seed1".as_ref(), &other)?;
//! let mut config = weft_nn::altconv::AltConvTrainingSettings::default();
//! config.hidden = vec![8, 8];
//! config.steps = 4;
//! config.epochs = 2;
//! let limb = LimbDataset::load("data/limb".as_ref())?;
//! let mut progress = weft_nn::trainer::EpochLines;
//! weft_nn::altconv::train_model("models/alt".as_ref(), &limb, &config, &mut progress)?;
//! let output = score(&ScoreOptions {
//!     kind: ModelKind::Altconv,
//!     model: "models/alt".into(),
//!     data: "data/limb-seed1".into(),
//!     split: "test".into(),
//!     out: "scores/alt".into(), // results.json and predictions/
//! })?;
//! assert!(output.records.iter().all(|r| r.value.is_finite()));
//! # Ok::<(), weft_experiments::Error>(())
//! ```
//!
//! The whole evaluation of one experiment, with its report:
//!
//! ```no_run
//! use weft_experiments::evaluate::{EvaluateOptions, run};
//! use weft_data::Size;
//! let mut options = EvaluateOptions::new(Size::Quick);
//! options.only = vec!["altconv".into()];
//! options.out = "out/altconv-quick".into();
//! run(&options)?; // the limb dataset, five trained models, out/altconv-quick/index.html
//! # Ok::<(), weft_experiments::Error>(())
//! ```

pub mod error;
pub mod evaluate;
pub mod files;
#[cfg(test)]
mod layers;
pub mod paper;
pub mod progress;
pub mod records;
pub mod render;
pub mod report;
pub mod score;
pub mod stability;

pub use error::{Context, Error, Result};
