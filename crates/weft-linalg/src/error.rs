//! The one error type of weft-linalg.

/// Errors of the sparse solvers.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    #[error("matrix is not positive definite (Cholesky failed); an SPD projection or more regularisation is needed")]
    NotPositiveDefinite,
    #[error("factorisation setup failed: {0}")]
    Setup(String),
    #[error("{what}: expected length {expected}, got {got}")]
    DimensionMismatch {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("the two matrices have different sparsity patterns")]
    PatternMismatch,
    #[error("non-finite value in {0}")]
    NonFinite(&'static str),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
