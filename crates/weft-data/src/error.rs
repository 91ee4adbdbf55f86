//! The error type of weft-data.

/// Everything that can go wrong reading, writing or generating a dataset, by cause.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    #[error("I/O error on {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A dataset file is missing an array, has one of the wrong shape or a non-finite
    /// value, or does not fit the rest of the dataset.
    #[error("dataset file {path}: {reason}")]
    Dataset { path: String, reason: String },
    /// A dataset file's SHA-256 is not the one its manifest recorded.
    #[error(
        "dataset file {path}: SHA-256 {actual} does not match the manifest's {expected} (the file changed after it was written)"
    )]
    Checksum {
        path: String,
        expected: String,
        actual: String,
    },
    /// Arrays whose lengths disagree.
    #[error("{what}: expected {expected}, got {got}")]
    Shape {
        what: &'static str,
        expected: String,
        got: String,
    },
    /// A request that cannot be met as asked: an unknown dataset, a zero count, a
    /// directory holding another dataset, shards that do not fit together.
    #[error("{0}")]
    Invalid(String),
    /// Part of the data could not be generated (a drape chunk found no converged pose).
    #[error("{0}")]
    Incomplete(String),
    #[error(transparent)]
    Mesh(#[from] weft_mesh::Error),
    #[error(transparent)]
    Sim(#[from] weft_sim::Error),
    #[error("safetensors: {0}")]
    Safetensors(#[from] safetensors::SafeTensorError),
    #[error("JSON: {0}")]
    Json(#[from] serde_json::Error),
    #[error("progress bar template: {0}")]
    Template(#[from] indicatif::style::TemplateError),
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
    /// An I/O error on `path`.
    pub fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.display().to_string(),
            source,
        }
    }
}

/// Defines a crate's `Context` trait: `.context(...)` and `.with_context(...)` on results
/// and options, adding what was being done to an error — anyhow's `Context`, for a typed
/// error. Written once here, the lowest crate that needs it; weft-experiments invokes it too.
///
/// `context_trait!(Error, Error::Variant)` needs, in scope, an `Error` enum with a
/// `Context { context: String, source: Box<Error> }` variant, which wraps any error that
/// converts `Into<Error>`; an absent `Option` becomes `Error::Variant(context)`. The trait is
/// generated per crate (not generic over the error) so that `x.context("...")?` infers its
/// error type from the crate it is written in.
#[macro_export]
macro_rules! context_trait {
    ($error:ident, $missing:path) => {
        /// `.context(...)` on results and options, adding what was being done to an error
        /// (defined by `weft_data::context_trait!`).
        pub trait Context<T> {
            fn context(self, context: impl ::std::fmt::Display) -> ::std::result::Result<T, $error>;
            fn with_context<C: ::std::fmt::Display>(self, f: impl FnOnce() -> C) -> ::std::result::Result<T, $error>;
        }

        impl<T, E: ::std::convert::Into<$error>> Context<T> for ::std::result::Result<T, E> {
            fn context(self, context: impl ::std::fmt::Display) -> ::std::result::Result<T, $error> {
                self.map_err(|e| $error::Context {
                    context: context.to_string(),
                    source: ::std::boxed::Box::new(e.into()),
                })
            }
            fn with_context<C: ::std::fmt::Display>(self, f: impl FnOnce() -> C) -> ::std::result::Result<T, $error> {
                self.map_err(|e| $error::Context {
                    context: f().to_string(),
                    source: ::std::boxed::Box::new(e.into()),
                })
            }
        }

        impl<T> Context<T> for ::std::option::Option<T> {
            fn context(self, context: impl ::std::fmt::Display) -> ::std::result::Result<T, $error> {
                self.ok_or_else(|| $missing(context.to_string()))
            }
            fn with_context<C: ::std::fmt::Display>(self, f: impl FnOnce() -> C) -> ::std::result::Result<T, $error> {
                self.ok_or_else(|| $missing(f().to_string()))
            }
        }
    };
}

context_trait!(Error, Error::Invalid);

/// Returns an [`Error::Invalid`] with a formatted message unless `cond` holds.
macro_rules! ensure {
    ($cond:expr, $($fmt:tt)+) => {
        if !$cond {
            return Err($crate::Error::Invalid(format!($($fmt)+)));
        }
    };
}
pub(crate) use ensure;
