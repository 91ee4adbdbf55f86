//! The error type of weft-experiments.

/// Everything that can go wrong running an experiment, scoring a model or writing and
/// checking a report, by cause.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    #[error(transparent)]
    Data(#[from] weft_data::Error),
    #[error(transparent)]
    Nn(#[from] weft_nn::Error),
    #[error(transparent)]
    Surrogate(#[from] weft_surrogate::Error),
    #[error(transparent)]
    Sim(#[from] weft_sim::Error),
    #[error(transparent)]
    Mesh(#[from] weft_mesh::Error),
    #[error(transparent)]
    Acap(#[from] weft_acap::Error),
    #[error(transparent)]
    Proj(#[from] weft_proj::Error),
    #[error(transparent)]
    Linalg(#[from] weft_linalg::Error),
    #[error("I/O: {0}")]
    Io(#[from] std::io::Error),
    #[error("JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error("safetensors: {0}")]
    Safetensors(#[from] safetensors::SafeTensorError),
    #[error("progress bar template: {0}")]
    Template(#[from] indicatif::style::TemplateError),
    /// Drawing a plot or a render failed.
    #[error("plot: {0}")]
    Plot(String),
    /// A request that cannot be met as asked (an unknown experiment, a size an
    /// experiment does not run at, an output directory holding another size).
    #[error("{0}")]
    Invalid(String),
    /// An experiment or a check found what it must not: a model that scored nothing, a
    /// report missing a file, a record with a bad field.
    #[error("{0}")]
    Failed(String),
    /// Starting this process anew failed (the command's executable, or its `exec`).
    #[error("{what}")]
    Exec {
        what: String,
        #[source]
        source: std::io::Error,
    },
    /// Another error, with what was being done when it happened (the cause is its
    /// `source()`; `anyhow`'s `{:#}` prints the whole chain).
    #[error("{context}")]
    Context {
        context: String,
        #[source]
        source: Box<Error>,
    },
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// A plotting error (plotters' errors carry their backend's type).
    pub fn plot(e: impl std::fmt::Debug) -> Self {
        Self::Plot(format!("{e:?}"))
    }
}

impl<E: std::error::Error + Send + Sync> From<plotters::drawing::DrawingAreaErrorKind<E>> for Error {
    fn from(e: plotters::drawing::DrawingAreaErrorKind<E>) -> Self {
        Self::plot(e)
    }
}

weft_data::context_trait!(Error, Error::Failed);

/// Returns an [`Error::Failed`] with a formatted message unless `cond` holds.
macro_rules! ensure {
    ($cond:expr, $($fmt:tt)+) => {
        if !$cond {
            return Err($crate::Error::Failed(format!($($fmt)+)));
        }
    };
}

/// Returns an [`Error::Failed`] with a formatted message.
macro_rules! bail {
    ($($fmt:tt)+) => {
        return Err($crate::Error::Failed(format!($($fmt)+)))
    };
}
pub(crate) use {bail, ensure};
