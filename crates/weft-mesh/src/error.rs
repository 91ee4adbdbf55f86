//! The one error type of weft-mesh.

use std::path::PathBuf;

/// Everything that can be wrong with a mesh or a mesh file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    #[error("mesh has no vertices")]
    NoVertices,
    #[error("mesh has no {what}")]
    NoElements { what: &'static str },
    #[error("vertex {vertex} has a non-finite coordinate ({x}, {y}, {z})")]
    NonFiniteCoordinate { vertex: usize, x: f64, y: f64, z: f64 },
    #[error("{element} {index} refers to vertex {vertex}, but there are only {num_vertices} vertices")]
    IndexOutOfRange {
        element: &'static str,
        index: usize,
        vertex: usize,
        num_vertices: usize,
    },
    #[error("{element} {index} repeats vertex {vertex}")]
    RepeatedIndex {
        element: &'static str,
        index: usize,
        vertex: usize,
    },
    #[error("edge ({a}, {b}) is shared by {count} faces; a surface allows at most 2")]
    NonManifoldEdge { a: usize, b: usize, count: usize },
    #[error("edge ({a}, {b}) is traversed in the same direction by two faces: orientation is inconsistent")]
    InconsistentOrientation { a: usize, b: usize },
    #[error("face {face} has area {area:e}, at or below the tolerance {tolerance:e}")]
    DegenerateFace { face: usize, area: f64, tolerance: f64 },
    #[error("tetrahedron {tet} has signed volume {volume:e}: {}", tet_volume_problem(*.volume))]
    BadTetVolume { tet: usize, volume: f64 },
    #[error("{what}: expected {expected} entries, got {got}")]
    LengthMismatch {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("invalid generator parameter: {0}")]
    InvalidParameter(String),
    #[error("{path}:{line}: {message}")]
    Parse {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error("unsupported mesh file extension {extension:?} for {path} (supported: {supported})")]
    UnsupportedFormat {
        path: PathBuf,
        extension: String,
        supported: &'static str,
    },
    #[error("I/O error on {path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
}

/// `Result` with weft-mesh's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// What is wrong with a tetrahedron's signed volume, for [`Error::BadTetVolume`].
fn tet_volume_problem(volume: f64) -> &'static str {
    if volume < 0.0 {
        "inverted"
    } else if !volume.is_finite() {
        "not a finite volume"
    } else if volume == 0.0 {
        "zero volume"
    } else {
        "degenerate (at or below 1e-14 × the cube of the mesh's bounding-box diagonal)"
    }
}
