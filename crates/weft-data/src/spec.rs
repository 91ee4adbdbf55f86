//! What a dataset is: its name, [`Size`], sequence and frame counts, [`Split`], the scene
//! its sequences are seeded from, and the seed of each sequence. Generation
//! ([`generate`](mod@crate::generate)) and the dataset kinds ([`crate::drape`], [`crate::nnwarp`]) build
//! on it.

use serde::{Deserialize, Serialize};
use weft_sim::AnyScene;

use crate::error::{Context, Result, ensure};
use crate::files::Array;

/// The name of the `drape` dataset (the close-fitting sleeve).
pub const DRAPE: &str = "drape";
/// The name of the `drape-loose` dataset (the loose sleeve, issue 33).
pub const DRAPE_LOOSE: &str = "drape-loose";

/// Whether `name` is one of the drape datasets (the same chunked layout and reader).
pub fn is_drape(name: &str) -> bool {
    name == DRAPE || name == DRAPE_LOOSE
}
/// The name of the `nnwarp` dataset.
pub const NNWARP: &str = "nnwarp";

/// Examples per split and per chunk of drape dataset `name` at a size: (train,
/// validation, test, chunk). Geng et al. §4.1: 1000 training examples (Table 1) and 8000
/// (Table 2); the validation and test sets are not sized in the paper, we use 200 each.
/// The loose sleeve's standard set is 600 / 100 / 100: its solves cost several times the
/// close-fitting sleeve's, and its evaluation trains every method with three seeds
/// (docs/DRAPE.md, "Cost of the loose sleeve's standard run"); its network-only
/// data-size curve is reported with it.
pub fn drape_counts(name: &str, size: Size) -> (usize, usize, usize, usize) {
    match (size, name == DRAPE_LOOSE) {
        (Size::Quick, _) => (16, 4, 4, 4),
        (Size::Standard, false) => (1000, 200, 200, 50),
        (Size::Standard, true) => (600, 100, 100, 50),
        (Size::Paper, _) => (8000, 200, 200, 50),
    }
}

/// The datasets: every built-in cloth scene (Tan et al. §VI, design §3), the
/// soft-tissue `limb` (design §6), NNWarp's registered beam sequences (design §7) and
/// the sleeve `drape` and loose-sleeve `drape-loose` examples (design §8).
pub fn dataset_names() -> Vec<&'static str> {
    weft_sim::BUILTIN_SCENES
        .iter()
        .copied()
        .chain(weft_sim::scenes::load::SOFT_TISSUE_SCENES)
        .chain([NNWARP, DRAPE, DRAPE_LOOSE])
        .collect()
}

/// One generated sequence as it is stored.
#[derive(Debug)]
pub struct StoredSequence {
    pub arrays: Vec<Array>,
    pub metadata: std::collections::HashMap<String, String>,
    /// Frames stored, the initial state included.
    pub frames: usize,
    /// Frames computed (timed), and the solver's seconds over them.
    pub simulated_frames: usize,
    pub solver_seconds: f64,
    /// Why the sequence stopped early, if it did.
    pub error: Option<String>,
}

/// How big a dataset (or an evaluation) is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Size {
    /// Seconds: small meshes, few frames — tests and smoke runs.
    Quick,
    /// What the committed evaluation uses: full meshes, each experiment within about an hour here.
    Standard,
    /// The papers' sizes (see docs/DATASETS.md for the estimated time).
    Paper,
}

impl Size {
    pub const ALL: [Size; 3] = [Size::Quick, Size::Standard, Size::Paper];

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Quick => "quick",
            Self::Standard => "standard",
            Self::Paper => "paper",
        }
    }
}

impl std::fmt::Display for Size {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Size {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Size::ALL
            .into_iter()
            .find(|z| z.as_str() == s)
            .ok_or_else(|| format!("{s:?} is not a size (quick, standard or paper)"))
    }
}

/// What a dataset holds at a size.
#[derive(Debug, Clone)]
pub struct DatasetSpec {
    pub name: String,
    pub size: Size,
    pub sequences: usize,
    /// Frames simulated per sequence (the stored arrays hold one more: the initial state).
    pub frames: usize,
    /// The scene before per-sequence seeding.
    pub scene: AnyScene,
    pub split: Split,
}

impl DatasetSpec {
    /// Frames stored per sequence: the simulated ones and the initial state, or for
    /// `drape` the examples of a chunk.
    pub fn stored_frames(&self) -> usize {
        if is_drape(&self.name) {
            self.frames
        } else {
            self.frames + 1
        }
    }
}

/// How a dataset is split into train / validation / test.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Split {
    /// Tan et al. §VI: in every sequence, the first 12 of every 17 frames train, the other 5 test.
    #[serde(rename = "frames-12-of-17")]
    Frames12Of17,
    /// Whole sequences, in index order: 62 % train, 15.5 % validation, the rest test
    /// (Alt-ConvLSTM §5.1's 80 / 20 / 29 of 129).
    Sequences,
    /// Whole sequences (chunks of examples), in index order: the first `train` train, the
    /// next `validation` validate, the rest test.
    Chunks { train: usize, validation: usize },
}

impl Split {
    /// The split of sequence `i` of `n` (`"all"` when frames are split within sequences).
    pub fn of_sequence(self, i: usize, n: usize) -> &'static str {
        match self {
            Self::Frames12Of17 => "all",
            Self::Sequences => {
                let train = (0.62 * n as f64).round() as usize;
                let val = (0.155 * n as f64).round().max(1.0) as usize;
                if i < train {
                    "train"
                } else if i < train + val {
                    "validation"
                } else {
                    "test"
                }
            }
            Self::Chunks { train, validation } => {
                if i < train {
                    "train"
                } else if i < train + validation {
                    "validation"
                } else {
                    "test"
                }
            }
        }
    }
}

impl DatasetSpec {
    pub fn new(name: &str, size: Size) -> Result<Self> {
        ensure!(
            dataset_names().contains(&name),
            "unknown dataset {name:?}; datasets are: {}",
            dataset_names().join(", ")
        );
        let quick = size == Size::Quick;
        if is_drape(name) {
            // A "sequence" is a chunk of independent examples; "frames" its size.
            let (train, validation, test, chunk) = drape_counts(name, size);
            return Ok(Self {
                name: name.into(),
                size,
                sequences: (train + validation + test) / chunk,
                frames: chunk,
                scene: AnyScene::SoftTissue(weft_sim::SoftTissueScene::builtin(quick)),
                split: Split::Chunks {
                    train: train / chunk,
                    validation: validation / chunk,
                },
            });
        }
        if name == NNWARP {
            // The training beam (12 × 6 × 6 cells, 2592 tets; quick 6 × 3 × 3); the
            // sequence count and ramp frames by size. The paper trains on 520 sequences
            // (20 829 poses); the 62 / 15.5 / 22.5 % split of 839 gives exactly 520
            // training sequences, 130 validation and 189 test ones. Standard is the
            // paper's size: with 40 training sequences the networks were data-limited
            // (docs/NNWARP.md, data-size study), and the 839 cost about an hour on two
            // cores.
            let (sequences, frames) = match size {
                Size::Quick => (16, 8),
                Size::Standard | Size::Paper => (839, 40),
            };
            return Ok(Self {
                name: name.into(),
                size,
                sequences,
                frames,
                scene: AnyScene::Volume(weft_sim::VolumeScene::builtin("beam-neo-hookean", quick)?),
                split: Split::Sequences,
            });
        }
        let scene = weft_sim::scenes::load::builtin(name, quick)?.context("built-in scene missing")?;
        let ball = name.starts_with("ball");
        let (sequences, frames, split) = match (name, size) {
            ("limb" | "limb-jiggle", Size::Quick) => (4, 8, Split::Sequences),
            ("limb" | "limb-jiggle", Size::Standard) => (20, 60, Split::Sequences),
            // Dynamic FAUST's 129 sequences, at about 2 s each.
            ("limb" | "limb-jiggle", Size::Paper) => (129, 120, Split::Sequences),
            (_, Size::Quick) => (3, 34, Split::Frames12Of17),
            (_, Size::Standard) => (4, 170, Split::Frames12Of17),
            // Tan et al. §VI: each of the SHEET and BALL datasets' four sequences is one
            // scene (mass-spring, holes, FEM, obstacle or softer material), so a scene has
            // one sequence, of 2400 (sheets) or 500 (balls) frames.
            (_, Size::Paper) => (1, if ball { 500 } else { 2400 }, Split::Frames12Of17),
        };
        Ok(Self {
            name: name.into(),
            size,
            sequences,
            frames,
            scene,
            split,
        })
    }

    /// The scene of sequence `i`: seeded from (dataset seed, i); cloth programs start at
    /// segment `i mod segments` so every sequence covers different motions (segments
    /// start and end at the rest offset, so the rotation is continuous).
    pub fn sequence_scene(&self, seed: u64, i: usize) -> AnyScene {
        let s = sequence_seed(seed, i);
        let mut scene = self.scene.clone();
        scene.set_frames(self.frames);
        match &mut scene {
            AnyScene::Cloth(c) => {
                c.seed = s;
                let k = i % c.program.len();
                c.program.rotate_left(k);
            }
            AnyScene::SoftTissue(t) => t.params.seed = s,
            AnyScene::Volume(_) => {}
        }
        scene
    }
}

/// Seed of sequence `i` of a dataset with seed `seed`: one SplitMix64 step from
/// `seed + (i + 1)·φ` (φ = 0x9E3779B97F4A7C15), so neighbouring indices and seeds give
/// unrelated streams.
pub fn sequence_seed(seed: u64, i: usize) -> u64 {
    weft_sim::rng::SplitMix64::new(seed.wrapping_add((i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))).next_u64()
}
