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
//! - [`progress`]: a training run's progress bar and epoch lines.
//!
//! What is not here: no physics, features, projections or networks of its own (weft-sim,
//! weft-acap, weft-proj, weft-nn), no dataset format (weft-data), no command line (xtask
//! parses arguments into [`evaluate::EvaluateOptions`] and the like).
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
pub mod paper;
pub mod progress;
pub mod records;
pub mod render;
pub mod report;
pub mod score;
pub mod stability;

pub use error::{Context, Error, Result};
