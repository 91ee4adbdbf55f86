//! The error type of weft-nn.

/// Everything that can go wrong in weft-nn, by cause.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A tensor operation failed (shape mismatch inside candle, unsupported dtype, …).
    #[error("tensor operation failed: {0}")]
    Candle(#[from] candle_core::Error),
    /// ACAP⁻¹ or its vector–Jacobian product failed.
    #[error(transparent)]
    Acap(#[from] weft_acap::Error),
    /// A projection layer's solve or backward pass failed.
    #[error(transparent)]
    Proj(#[from] weft_proj::Error),
    /// The physics (L_phys and its gradient) failed.
    #[error(transparent)]
    Sim(#[from] weft_sim::Error),
    /// A dense or sparse solve failed (a fit's normal equations).
    #[error(transparent)]
    Linalg(#[from] weft_linalg::Error),
    /// A closed-form surrogate or the PCA failed (weft-surrogate), or a model directory
    /// is of another kind.
    #[error(transparent)]
    Surrogate(#[from] weft_surrogate::Error),
    /// Writing a mesh file failed.
    #[error(transparent)]
    Mesh(#[from] weft_mesh::Error),
    /// An input has the wrong shape for what it feeds.
    #[error("{what}: expected shape {expected}, got {got}")]
    Shape {
        what: &'static str,
        expected: String,
        got: String,
    },
    /// A value crossing from the network into the physics (or back) is NaN or infinite.
    #[error("{what} has a non-finite entry at flat index {index}")]
    NonFinite { what: &'static str, index: usize },
    /// A configuration value is out of its range.
    #[error("invalid {name} = {value}: {reason}")]
    InvalidParameter {
        name: &'static str,
        value: String,
        reason: &'static str,
    },
    /// A training configuration field is out of its range: checked before any work, so
    /// nothing is written.
    #[error("configuration field `{field}` = {value} {reason}")]
    InvalidSettings {
        field: String,
        value: String,
        reason: &'static str,
    },
    /// A later training stage was asked for without the earlier stage it starts from.
    #[error(
        "{dir} holds no trained stage {stage}, which the stages asked for start from; train it first (e.g. --stages \
         1,2,3, or leave out --stages)"
    )]
    MissingStage { stage: u8, dir: String },
    /// A checkpoint is missing a tensor, has one of the wrong shape, or does not belong to
    /// this model.
    #[error("checkpoint {path}: {reason}")]
    Checkpoint { path: String, reason: String },
    /// A dataset file is missing an array, has one of the wrong shape or a non-finite
    /// value, or does not fit the rest of the dataset.
    #[error("dataset file {path}: {reason}")]
    Dataset { path: String, reason: String },
    /// Reading a dataset failed (a missing or changed file, a bad array).
    #[error(transparent)]
    Data(#[from] weft_data::Error),
    /// Reading the dataset in a directory failed (the cause follows).
    #[error("loading {path}")]
    Load {
        path: String,
        #[source]
        source: Box<Error>,
    },
    /// `--train-examples` asked for none, or for more than the training split holds.
    #[error("--train-examples {asked}: {data} has {available} training examples")]
    TrainExamples {
        asked: usize,
        data: String,
        available: usize,
    },
    /// A training run needs training and validation examples.
    #[error("{data} needs training and validation examples (it has {train} and {validation})")]
    TooFewExamples {
        data: String,
        train: usize,
        validation: usize,
    },
    /// A flag's value is out of its range.
    #[error("{flag} {reason}")]
    InvalidFlag { flag: &'static str, reason: &'static str },
    /// A volumetric model was asked to run on a scene of another kind.
    #[error("{scene} is not a volumetric scene; NNWarp warps tetrahedral bodies")]
    NotVolumetric { scene: String },
    /// An output directory could not be created.
    #[error("creating the output directory {path}")]
    CreateDir {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A warp run failed (the cause follows).
    #[error("running NNWarp against the full FEM reference")]
    WarpRun {
        #[source]
        source: Box<Error>,
    },
    /// A projection layer failed on every example scored (the first failure).
    #[error("the postprocess failed on every example: {first}")]
    PostprocessFailed { first: String },
    /// A training configuration file does not parse (or names an unknown field).
    #[error("parsing the configuration {path}: {reason}")]
    ConfigFile { path: String, reason: String },
    /// A training run would overwrite a model it was not asked to continue.
    #[error("{dir} already holds a model; pass --resume to continue it or choose another --out")]
    ModelExists { dir: String },
    #[error("I/O error on {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

/// weft-nn's result, with [`Error`] unless another error is named.
pub type Result<T, E = Error> = std::result::Result<T, E>;
