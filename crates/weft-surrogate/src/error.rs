//! The error type of weft-surrogate.

/// Everything that can go wrong fitting, storing or loading a surrogate, by cause.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// An input has the wrong shape for what it feeds.
    #[error("{what}: expected shape {expected}, got {got}")]
    Shape {
        what: &'static str,
        expected: String,
        got: String,
    },
    /// An input or a prediction is NaN or infinite.
    #[error("{what} has a non-finite entry at flat index {index}")]
    NonFinite { what: &'static str, index: usize },
    /// A setting or argument is out of its range.
    #[error("invalid {name} = {value}: {reason}")]
    InvalidParameter {
        name: &'static str,
        value: String,
        reason: &'static str,
    },
    /// A model directory is missing a file or an array, does not parse, holds a model of
    /// another kind, or its parts do not fit together.
    #[error("checkpoint {path}: {reason}")]
    Checkpoint { path: String, reason: String },
    /// Reading the training dataset or writing a model file failed.
    #[error(transparent)]
    Data(#[from] weft_data::Error),
    /// The normal equations of a fit could not be solved.
    #[error(transparent)]
    Linalg(#[from] weft_linalg::Error),
    #[error("I/O error on {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

/// weft-surrogate's result, with [`Error`] unless another error is named.
pub type Result<T, E = Error> = std::result::Result<T, E>;
