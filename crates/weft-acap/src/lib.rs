//! ACAP deformation features and their differentiable inverse.
//!
//! Tan et al. (RA-L 2020, §III-A) embed cloth and soft-body meshes in the ACAP feature
//! space of Gao et al. (*Sparse Data Driven Mesh Deformation*): per vertex, the
//! deformation gradient T_i that best maps the rest 1-ring onto the deformed one (Eq. 1),
//! its polar decomposition T = R S, and the 9-D feature (log R, upper triangle of S),
//! with log R made consistent across neighbours so that twists beyond π stay
//! continuous. This crate computes those features ([`AcapFeatures`]), scales them for
//! tanh outputs ([`FeatureNormalization`]), and inverts them ([`PoissonPseudoInverse`],
//! Tan et al. §IV-A, Eq. 6): Rodrigues, T = R S, then the least-squares positions with
//! the grasp points pinned, factorised once per rest mesh and pin set, with a
//! vector–Jacobian product that reuses the factorisation.
//!
//! It is deliberately not a neural-network crate (weft-nn wraps the inverse as a candle
//! custom op), does no file I/O (xtask does), and has no mixed-integer solver: the
//! consistency of log R uses the propagation-and-sweep algorithm of `docs/ACAP.md` §A3 (see
//! [`ConsistencyReport`]). Flat rest meshes, where the rest edge covariance is rank 2,
//! are kept well posed by an extra normal pair in Eq. 1 (see [`AcapFeatures`]).
//!
//! Units: positions in metres, rotation angles in radians; `f64` throughout.
//!
//! ```
//! use weft_acap::{AcapFeatures, AcapSettings, PoissonPseudoInverse, ReconstructionError};
//! use nalgebra::Vector3;
//!
//! let rest = weft_mesh::generators::sheet(9, 1.0)?;
//! let acap = AcapFeatures::new(&rest, AcapSettings::default())?;
//! // Bend the sheet gently into a cylinder arc about an axis parallel to Y.
//! let radius = 1.5;
//! let bent: Vec<Vector3<f64>> = rest
//!     .positions()
//!     .iter()
//!     .map(|q| Vector3::new(radius * (q.x / radius).sin(), q.y, radius * (1.0 - (q.x / radius).cos())))
//!     .collect();
//! let features = acap.encode(&bent)?;
//! assert_eq!(features.len(), 81);
//!
//! // Pin two corners (the grasp points) and reconstruct.
//! let pins = [0, 8];
//! let inverse = PoissonPseudoInverse::new(&acap, &pins)?;
//! let decoded = inverse.decode(&features, &[bent[0], bent[8]])?;
//! let error = ReconstructionError::between(&bent, &decoded)?;
//! assert!(error.max_relative() < 1e-2); // per-vertex gradients are not exactly integrable
//! # Ok::<(), weft_acap::Error>(())
//! ```

mod consistency;
pub mod error;
mod features;
pub mod frames;
mod inverse;
mod normalization;
mod rings;
pub mod rotation;

/// The nalgebra this crate's API uses (`Vector3<f64>`, `Matrix3<f64>`), re-exported so
/// callers need not pin a matching version.
pub use nalgebra;

pub use consistency::ConsistencyReport;
pub use error::{Error, Result};
pub use features::{
    AcapFeatures, AcapSettings, EdgeWeights, Feature, LOG_ROTATION_BLOCK, STRETCH_BLOCK, feature_from_parts,
    feature_log_rotation, feature_stretch,
};
pub use inverse::{DecodeGradient, PoissonPseudoInverse, ReconstructionError};
pub use normalization::{FeatureNormalization, NORMALIZED_BOUND};
