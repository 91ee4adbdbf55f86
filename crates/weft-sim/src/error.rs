//! The one error type of weft-sim.

/// What can go wrong building or stepping a simulation.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    #[error(transparent)]
    Mesh(#[from] weft_mesh::Error),
    #[error(transparent)]
    Linalg(#[from] weft_linalg::Error),
    #[error(
        "Newton did not converge: residual {residual:e} N after {iterations} iterations (tolerance {tolerance:e} N)"
    )]
    NotConverged {
        iterations: usize,
        residual: f64,
        tolerance: f64,
    },
    #[error(
        "the warped static solve did not settle: successive displacements still differ by {change:e} of their \
         largest after {solves} solves (the load is far past the linear regime)"
    )]
    WarpNotSettled { solves: usize, change: f64 },
    #[error("a warped static solve needs a static (stiffness-only) linear system")]
    NotStatic,
    #[error("non-finite {what} (at DOF {dof}); the step was rejected")]
    NonFinite { what: &'static str, dof: usize },
    #[error("invalid parameter {name} = {value}: {reason}")]
    InvalidParameter {
        name: &'static str,
        value: f64,
        reason: &'static str,
    },
    #[error("{what}: expected {expected} entries, got {got}")]
    LengthMismatch {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("vertex index {index} out of range ({num_vertices} vertices) in {what}")]
    VertexOutOfRange {
        what: &'static str,
        index: usize,
        num_vertices: usize,
    },
    #[error(
        "the anchors leave {free_rigid_modes} rigid motion(s) of the body free, so the static system is singular; \
         anchor at least three non-collinear nodes"
    )]
    UnderConstrained { free_rigid_modes: usize },
    #[error(
        "the garment came off the body: vertex {vertex} ended {distance:.3} m from its kinematic guess, more than \
         {limit:.3} m (half the garment's length)"
    )]
    GarmentOffBody { vertex: usize, distance: f64, limit: f64 },
    #[error("surrogate {surrogate:?} does not fit: its {what} is {got}, the scene's is {expected}")]
    SurrogateMismatch {
        surrogate: String,
        what: &'static str,
        expected: String,
        got: String,
    },
    #[error("surrogate {surrogate:?} failed to propose a frame: {source}")]
    Surrogate {
        surrogate: String,
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    #[error("scene error: {0}")]
    Scene(String),
}

/// `Result` with weft-sim's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

pub(crate) fn check_positive(name: &'static str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(Error::InvalidParameter {
            name,
            value,
            reason: "must be positive and finite",
        })
    }
}

pub(crate) fn check_nonnegative(name: &'static str, value: f64) -> Result<()> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(Error::InvalidParameter {
            name,
            value,
            reason: "must be non-negative and finite",
        })
    }
}
