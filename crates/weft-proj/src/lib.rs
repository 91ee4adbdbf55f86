//! Physics projection layers for weft (Geng, Johnson, Fedkiw, *Coercing Machine Learning
//! to Output Physically Accurate Results*): functions that map a network's predicted
//! cloth configuration `r̂` to a physically better one `r*`, each with a hand-written
//! backward pass `∂E/∂r* ↦ ∂E/∂r̂` so they can sit inside training.
//!
//! - [`InextensibilityLayer`] (§3–4): the mass-weighted closest configuration whose
//!   edges stretch at most `(1 + ε)` times their rest length — a second-order cone
//!   program solved by our primal–dual interior-point method on the reduced `3V × 3V`
//!   normal equations (Clarabel selectable for cross-checks) and polished by Newton on
//!   its active set, differentiated through the conic optimality conditions with one
//!   sparse LDLᵀ solve (Eq. 6–11, Appendix A).
//! - [`QuasistaticLayer`] (§5–6): the equilibrium of edge, bending and axial springs tied
//!   to `r̂` by zero-length springs of scale `μ` (global or per vertex), solved by
//!   weft-sim's Newton method and differentiated by one adjoint solve (Eq. 12–16),
//!   including `∂E/∂μ`.
//!
//! Both have a batch API that runs examples in parallel with rayon (the sparse
//! factorisations inside stay single-threaded). `docs/PROJECTION.md` derives the systems
//! that are differentiated and lists measured timings.
//!
//! This crate is plain numerics: it does not depend on candle (weft-nn wraps these
//! layers as custom ops), reads no files, and has no second copy of a spring energy,
//! Newton solver or sparse factorisation — those come from weft-sim and weft-linalg.
//!
//! ```
//! use weft_proj::{InextensibilityLayer, SocpSettings};
//! let rest = weft_mesh::generators::sheet(4, 1.0)?;
//! let layer = InextensibilityLayer::new(&rest, 0.1, SocpSettings::default())?;
//! // A prediction stretched by 50 % along x.
//! let pred: Vec<f64> = rest.flat_positions().iter().enumerate()
//!     .map(|(i, x)| if i % 3 == 0 { 1.5 * x } else { *x }).collect();
//! let (solution, report) = layer.forward(&pred)?;
//! assert!(report.max_violation <= 1e-6);
//! // Backward: gradient of E = Σ r*_x with respect to the prediction.
//! let grad_out: Vec<f64> = (0..pred.len()).map(|i| if i % 3 == 0 { 1.0 } else { 0.0 }).collect();
//! let grad_in = layer.backward(&solution, &grad_out)?;
//! assert_eq!(grad_in.len(), pred.len());
//! # Ok::<(), weft_proj::Error>(())
//! ```

pub mod axial;
mod batch;
pub mod error;
pub mod files;
mod ipm;
mod kkt;
mod krylov;
pub mod metrics;
pub mod quasistatic;
pub mod rest;
pub mod socp;

pub use axial::AxialSprings;
pub use batch::WarmStarts;
pub use error::{Error, Result};
pub use metrics::{StrainSummary, strain_summary};
pub use quasistatic::{
    QuasistaticAdjoint, QuasistaticGradient, QuasistaticLayer, QuasistaticParams, QuasistaticReport,
    QuasistaticSolution, QuasistaticSolver, ZeroLengthScaling,
};
pub use rest::RestShape;
pub use socp::{
    BackwardReport, ConicSolver, HANDOVER_TOLERANCE, InextensibilityLayer, SocpReport, SocpSettings, SocpSolution,
};
