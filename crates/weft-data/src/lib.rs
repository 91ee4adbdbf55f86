//! weft's datasets: what the learned models train on, generated from the ground-truth
//! simulators and read back checked.
//!
//! What is here:
//! - [`generate`](mod@generate): every built-in dataset — each built-in cloth scene (Tan et al. §VI), the
//!   soft-tissue `limb` (Alt-ConvLSTM), `nnwarp` (registered beam sequences, NNWarp §5) and
//!   `drape` (a sleeve on the posed limb, Geng et al.) — as independent sequences seeded
//!   from (dataset seed, index), so any slice can be computed anywhere ([`Shard`]), an
//!   interrupted run resumes, and shards [`merge`] into the bytes of an unsharded run; a
//!   [`Manifest`] records every file's SHA-256, the sizes ([`Size`]) and the split
//!   ([`Split`]);
//! - [`read`]: the readers training uses ([`ClothDataset`], [`WarpDataset`],
//!   [`LimbDataset`], [`DrapeDataset`]), which verify every file against the manifest's
//!   checksum and every array's shape and finiteness before handing frames on;
//! - [`record`]: the one frame-recording driver ([`Recorder`]) the generator, the
//!   `simulate` command and the evaluation step any scene through;
//! - [`arrays`]: loose `.npy` arrays (read and written) and the frames of a `simulate`
//!   output's safetensors, read checked;
//! - [`files`]: atomic file writing (a temporary name renamed into place), deterministic
//!   safetensors bytes, SHA-256, the progress-bar style.
//!
//! What is not here: no neural network or tensor library (weft-nn reads these datasets),
//! no command line (xtask parses arguments and calls [`generate()`]), no physics of its own
//! (every frame comes from weft-sim).
//!
//! Units are SI (metres, seconds); frames are flat `[x0, y0, z0, x1, …]` f64.
//!
//! ```no_run
//! use weft_data::{DatasetSpec, GenerateOptions, LimbDataset, Size, generate};
//! let dir = std::env::temp_dir().join("limb-quick");
//! let spec = DatasetSpec::new("limb", Size::Quick)?;
//! let manifest = generate(&spec, &dir, &GenerateOptions::default())?;
//! assert!(manifest.is_complete());
//! let limb = LimbDataset::load(&dir)?;
//! assert_eq!(limb.split("train").count(), 2);
//! # Ok::<(), weft_data::Error>(())
//! ```

pub mod acap_files;
pub mod arrays;
pub mod drape;
pub mod error;
pub mod files;
pub mod generate;
pub mod generate_all;
pub mod nnwarp;
pub mod read;
pub mod record;
pub mod simulate;
pub mod spec;

pub use error::{Context, Error, Result};
pub use generate::{
    FileEntry, GenerateOptions, Manifest, SequenceEntry, Shard, Timing, generate, merge, read_manifest, verify,
};
pub use read::{
    ClothDataset, ClothSequence, DrapeDataset, DrapeExample, LimbDataset, LimbSequence, RawArray, RawDataset,
    RawSequence, RawValues, WarpDataset, WarpSequence, is_train_frame, is_validation_frame,
};
pub use record::{FrameStats, NewtonDetail, Recorder, Recording};
pub use spec::{DatasetSpec, Size, Split, StoredSequence, dataset_names, sequence_seed};
