//! The one error type of weft-acap.

/// Everything that can go wrong computing or inverting ACAP features.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An error encoding one frame of several (or the chunk of frames from it).
    #[error("encoding frame {frame}: {source}")]
    AtFrame {
        frame: usize,
        #[source]
        source: Box<Error>,
    },
    #[error(
        "rest face {face} has area {area:e}: cotangent weights and normals are undefined on a collapsed rest triangle"
    )]
    DegenerateRestFace { face: usize, area: f64 },
    #[error(
        "vertex {vertex}: its rest 1-ring edges and normal do not span 3-D (edge covariance singular); is the vertex isolated?"
    )]
    DegenerateOneRing { vertex: usize },
    #[error("vertex {vertex} has a non-finite position ({x}, {y}, {z})")]
    NonFinitePosition { vertex: usize, x: f64, y: f64, z: f64 },
    #[error("face {face} collapsed in the deformed mesh: area {area:e} m² against {rest_area:e} m² at rest")]
    CollapsedFace { face: usize, area: f64, rest_area: f64 },
    #[error("vertex {vertex}: every face around it collapsed in the deformed mesh, so its normal is undefined")]
    DegenerateDeformedOneRing { vertex: usize },
    #[error("vertex {vertex}: non-finite value in its feature vector {feature:?}")]
    NonFiniteFeature { vertex: usize, feature: [f64; 9] },
    #[error("{what}: expected {expected} entries, got {got}")]
    LengthMismatch {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("pin {pin} is out of range for a mesh with {num_vertices} vertices")]
    PinOutOfRange { pin: usize, num_vertices: usize },
    #[error("vertex {pin} is pinned twice")]
    DuplicatePin { pin: usize },
    #[error(
        "the connected component containing vertex {vertex} has no pinned vertex, so its translation is undetermined"
    )]
    UnpinnedComponent { vertex: usize },
    #[error("pin position {index} (vertex {vertex}) is not finite")]
    NonFinitePin { index: usize, vertex: usize },
    #[error("the SVD of the deformation gradient at vertex {vertex} did not converge")]
    PolarDecomposition { vertex: usize },
    #[error("normalisation needs at least one feature vector")]
    EmptyTrainingSet,
    #[error("normalisation {what} {value} is not finite")]
    NonFiniteNormalization { what: &'static str, value: f64 },
    #[error("invalid setting: {0}")]
    InvalidSettings(String),
    #[error("the reconstructed positions are not finite (vertex {vertex}); the features are too large for the solve")]
    NonFiniteResult { vertex: usize },
    #[error(transparent)]
    Mesh(#[from] weft_mesh::Error),
    #[error(transparent)]
    Linalg(#[from] weft_linalg::Error),
}

/// `Result` with weft-acap's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
