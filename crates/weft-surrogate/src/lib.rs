//! Closed-form learned surrogates for weft-sim's guard (docs/GUARD.md, "A surrogate to
//! guard"): models fitted by linear algebra alone, so that everything which steps a scene
//! under the guard — the command line, the evaluation and the Python wheel — can load one
//! without a network library.
//!
//! What is here:
//! - [`pca`]: [`PositionPca`], principal components of flat frames from the Gram matrix
//!   (also the embedding experiment's linear baseline, through weft-nn);
//! - [`inertial_correction`]: [`InertialCorrection`], the inertial predictor
//!   `2p_{m−1} − p_{m−2}` plus a ridge-regressed correction in a PCA subspace of its
//!   residuals, fitted in closed form on a cloth dataset; its model directory
//!   (`fit_directory`, what `cargo xtask train inertial-correction` writes) and
//!   `load_surrogate`, which reads one as a [`weft_sim::guard::Surrogate`];
//! - [`model_dir`]: the model directory's files and the one test of which kind of weft
//!   model a directory holds, so another kind is refused by name.
//!
//! What is not here: no candle and no network (weft-nn holds those and re-exports this
//! crate's modules under its own paths), no guard (weft-sim's), no dataset generation
//! (weft-data's), no command line.
//!
//! ```
//! use weft_surrogate::PositionPca;
//! // Four frames of two coordinates on one line: one component reproduces them.
//! let frames: Vec<Vec<f64>> = [-1.0, -0.5, 0.5, 1.0].iter().map(|&t| vec![1.0 + t, 2.0 - t]).collect();
//! let pca = PositionPca::fit(&frames, 2)?;
//! assert_eq!(pca.num_components(), 1);
//! let back = pca.decode(&pca.encode(&frames[1]));
//! assert!(back.iter().zip(&frames[1]).all(|(a, b)| (a - b).abs() < 1e-12));
//! # Ok::<(), weft_surrogate::Error>(())
//! ```

pub mod error;
pub mod inertial_correction;
pub mod model_dir;
pub mod pca;

pub use error::{Error, Result};
pub use inertial_correction::{InertialCorrection, InertialCorrectionSettings, fit_directory, load_surrogate};
pub use pca::PositionPca;
