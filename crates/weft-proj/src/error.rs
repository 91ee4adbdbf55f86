//! The one error type of weft-proj.

/// What can go wrong building or running a projection layer.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    #[error(transparent)]
    Mesh(#[from] weft_mesh::Error),
    /// A mesh file to project cannot be read or does not fit the rest mesh.
    #[error("{0}")]
    MeshFile(String),
    #[error(transparent)]
    Sim(#[from] weft_sim::Error),
    #[error(transparent)]
    Linalg(#[from] weft_linalg::Error),
    #[error("{what}: expected {expected} entries, got {got}")]
    LengthMismatch {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("non-finite value in {what} at entry {index}")]
    NonFinite { what: &'static str, index: usize },
    #[error("invalid parameter {name} = {value}: {reason}")]
    InvalidParameter {
        name: &'static str,
        value: f64,
        reason: &'static str,
    },
    #[error("rest edge {edge} ({a}, {b}) has length {length:e} m; every rest edge must have positive length")]
    DegenerateRestEdge {
        edge: usize,
        a: usize,
        b: usize,
        length: f64,
    },
    #[error("vertex {vertex} has zero lumped mass in the rest mesh (it is in no face of positive area)")]
    MasslessVertex { vertex: usize },
    #[error("conic solver stopped with status {status} after {iterations} iterations")]
    SolverFailed { status: String, iterations: u32 },
    #[error("conic solver setup failed: {0}")]
    SolverSetup(String),
    #[error(
        "projection left edge {edge} at {ratio} × its rest length, above the bound (1 + ε) = {bound} by more than the tolerance"
    )]
    ConstraintViolated { edge: usize, ratio: f64, bound: f64 },
    #[error("{what} produced a non-finite value at entry {index}")]
    NonFiniteOutput { what: &'static str, index: usize },
    #[error(
        "the quasistatic equilibrium has {count} collapsed edge spring(s) (first: edge {first}); a spring with \
         coincident ends exerts no force, so this is a stationary point, not a minimum — the prediction is degenerate"
    )]
    CollapsedSprings { count: usize, first: usize },
    #[error(
        "the quasistatic equilibrium is not a minimum (its Hessian needed {shifts} diagonal shift(s) to factorise), so \
         its backward pass would differentiate another problem; perturb the prediction out of its symmetric state or \
         raise μ"
    )]
    NotAMinimum { shifts: usize },
}

/// `Result` with weft-proj's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Fails on the first non-finite entry of `values`.
pub(crate) fn check_finite(what: &'static str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(Error::NonFinite { what, index }),
        None => Ok(()),
    }
}

/// Fails unless `values` has `expected` entries.
pub(crate) fn check_len(what: &'static str, values: &[f64], expected: usize) -> Result<()> {
    if values.len() == expected {
        Ok(())
    } else {
        Err(Error::LengthMismatch {
            what,
            expected,
            got: values.len(),
        })
    }
}

/// Fails on the first non-finite entry of a computed output (never hand back NaN).
pub(crate) fn check_output(what: &'static str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(Error::NonFiniteOutput { what, index }),
        None => Ok(()),
    }
}
