//! Sharded, resumable datasets of independent simulated sequences (`cargo xtask dataset`).
//!
//! A dataset is a built-in scene run as `sequences` independent sequences. Sequence `i`
//! is seeded from `(dataset seed, i)` alone, so any subset can be computed on any machine
//! and gives the same bytes: `--shard i/n` computes one contiguous slice, `merge` joins
//! the slices and verifies every checksum. Every file is written atomically and the
//! manifest is rewritten after each sequence, so an interrupted run loses at most the
//! sequence it was computing and `--resume` continues from there. `docs/DATASETS.md`
//! documents the layout, the seeds and the sizes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use weft_sim::{AnyScene, LoadedScene};

use crate::error::{Context, Error, Result, ensure};
use crate::files::{
    Array, progress_bar, safetensors_bytes, sha256_file, sha256_hex, write_bytes, write_json, write_text,
};
use crate::record::Recorder;
use crate::{drape, nnwarp};

/// The datasets: every built-in cloth scene (Tan et al. §VI, design §3), the
/// soft-tissue `limb` (design §6), NNWarp's registered beam sequences (design §7) and
/// the sleeve `drape` examples (design §8).
pub fn dataset_names() -> Vec<&'static str> {
    weft_sim::BUILTIN_SCENES
        .iter()
        .copied()
        .chain([weft_sim::scenes::load::SOFT_TISSUE_SCENE, nnwarp::NAME, drape::NAME])
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

/// One slice of the sequences.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;
    /// `i/n`, e.g. `2/8`.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        parse_shard(s)
    }
}

fn parse_shard(s: &str) -> std::result::Result<Shard, String> {
    let (i, n) = s
        .split_once('/')
        .ok_or_else(|| format!("{s:?}: expected i/n, e.g. 0/4"))?;
    let index: usize = i
        .trim()
        .parse()
        .map_err(|_| format!("{s:?}: shard index is not a number"))?;
    let count: usize = n
        .trim()
        .parse()
        .map_err(|_| format!("{s:?}: shard count is not a number"))?;
    if count == 0 || index >= count {
        return Err(format!("{s:?}: need 0 ≤ i < n"));
    }
    Ok(Shard { index, count })
}

impl Shard {
    /// The contiguous range of sequence indices this shard computes.
    fn range(self, total: usize) -> std::ops::Range<usize> {
        (self.index * total / self.count)..((self.index + 1) * total / self.count)
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
        if self.name == drape::NAME {
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
        if name == drape::NAME {
            // A "sequence" is a chunk of independent examples; "frames" its size.
            let (train, validation, test, chunk) = drape::counts(size);
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
        if name == nnwarp::NAME {
            // The training beam (12 × 6 × 6 cells, 2592 tets; quick 6 × 3 × 3); the
            // sequence count and ramp frames by size (the paper: 20 829 poses).
            let (sequences, frames) = match size {
                Size::Quick => (16, 8),
                Size::Standard => (64, 40),
                Size::Paper => (520, 40),
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
            ("limb", Size::Quick) => (4, 8, Split::Sequences),
            ("limb", Size::Standard) => (20, 60, Split::Sequences),
            // Dynamic FAUST's 129 sequences, at about 2 s each.
            ("limb", Size::Paper) => (129, 120, Split::Sequences),
            (_, Size::Quick) => (3, 34, Split::Frames12Of17),
            (_, Size::Standard) => (4, 170, Split::Frames12Of17),
            // Tan et al. §VI: four sequences of 2400 (sheets) or 500 (balls) frames.
            (_, Size::Paper) => (4, if ball { 500 } else { 2400 }, Split::Frames12Of17),
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

/// A file of the dataset with its checksum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FileEntry {
    pub path: String,
    pub sha256: String,
}

/// One stored sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SequenceEntry {
    pub index: usize,
    pub seed: u64,
    pub split: String,
    /// Frames stored, the initial state included.
    pub frames: usize,
    pub path: String,
    pub sha256: String,
    /// Why the simulation stopped early, if it did (the frames before it are stored).
    pub error: Option<String>,
}

/// `manifest.json` (or `manifest-shard-<i>-of-<n>.json`): everything needed to verify and
/// reproduce the dataset. It holds no timings, so reruns give identical bytes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    pub dataset: String,
    pub size: Size,
    pub seed: u64,
    pub code_version: String,
    pub sequences_total: usize,
    pub frames_per_sequence: usize,
    pub split: Split,
    pub shard: Option<Shard>,
    pub files: Vec<FileEntry>,
    pub sequences: Vec<SequenceEntry>,
}

const FORMAT: &str = "weft-dataset/1";

impl Manifest {
    fn file_name(shard: Option<Shard>) -> String {
        match shard {
            None => "manifest.json".into(),
            Some(s) => format!("manifest-shard-{}-of-{}.json", s.index, s.count),
        }
    }
    /// The sequences this manifest is meant to hold.
    fn expected(&self) -> std::ops::Range<usize> {
        self.shard
            .map_or(0..self.sequences_total, |s| s.range(self.sequences_total))
    }
    pub fn is_complete(&self) -> bool {
        let want: Vec<usize> = self.expected().collect();
        let have: Vec<usize> = self.sequences.iter().map(|s| s.index).collect();
        want == have
    }
    fn same_dataset(&self, other: &Manifest) -> bool {
        self.format == other.format
            && self.dataset == other.dataset
            && self.size == other.size
            && self.seed == other.seed
            && self.code_version == other.code_version
            && self.sequences_total == other.sequences_total
            && self.frames_per_sequence == other.frames_per_sequence
            && self.split == other.split
            && self.files == other.files
    }
}

/// How a dataset is generated beyond its spec.
#[derive(Debug, Clone)]
pub struct GenerateOptions {
    /// Compute only this slice of the sequences.
    pub shard: Option<Shard>,
    /// Continue an interrupted run: sequences already written (and matching their
    /// checksums) are kept. Without it, a directory that holds a manifest is refused.
    pub resume: bool,
    /// The dataset seed; sequence `i`'s seed is derived from (seed, i).
    pub seed: u64,
    /// Hide the progress bar.
    pub quiet: bool,
    /// The code version the manifest records (a resumed run must be the same code): the
    /// command line passes its build's commit.
    pub code_version: String,
}

impl Default for GenerateOptions {
    fn default() -> Self {
        Self {
            shard: None,
            resume: false,
            seed: 0,
            quiet: true,
            code_version: concat!("weft-data ", env!("CARGO_PKG_VERSION")).to_string(),
        }
    }
}

/// Generation timings, kept out of the manifest so that reruns give identical bytes.
#[derive(Debug, Default, Serialize, Deserialize)]
pub struct Timing {
    /// Sequence index → (frames simulated, solver seconds, wall seconds).
    pub sequences: BTreeMap<usize, (usize, f64, f64)>,
}

/// Generates (or resumes) `spec` into `out`; returns the manifest written. Sequences
/// that stop early (a solve that does not converge) keep their frames up to the failure
/// and are reported as an [`Error::Incomplete`] after every other sequence is written.
pub fn generate(spec: &DatasetSpec, out: &Path, options: &GenerateOptions) -> Result<Manifest> {
    let GenerateOptions {
        shard,
        resume,
        seed,
        quiet,
        ref code_version,
    } = *options;
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let manifest_path = out.join(Manifest::file_name(shard));
    // The files every sequence shares: the base scene and its rest surface.
    let base = LoadedScene {
        scene: spec.scene.clone(),
        base_dir: None,
    };
    let scene_toml = base.scene.to_toml()?;
    // weft-mesh's writers (atomic, full precision) write the rest shape; they are
    // deterministic, so rewriting it on a resume leaves the same bytes.
    let rest_files: Vec<&str> = if spec.name == drape::NAME {
        // The sleeve and the body at the neutral pose, and the scene's parameters.
        let scene = weft_sim::scenes::drape::Drape::new(drape::params(spec.size))?;
        let sleeve = scene.sleeve();
        weft_mesh::io::write_obj(&out.join("sleeve.obj"), sleeve.positions(), sleeve.faces())?;
        let body = scene.body_rest();
        weft_mesh::io::write_obj(&out.join("body.obj"), body.positions(), body.faces())?;
        write_json(&out.join("drape.json"), scene.params())?;
        vec!["sleeve.obj", "body.obj", "drape.json"]
    } else if spec.name == nnwarp::NAME {
        // The volume itself, scaled into the unit sphere, as TetGen .node/.ele.
        let (body, _) = nnwarp::training_body(spec)?;
        weft_mesh::io::write_tetgen(&out.join("rest.node"), &body)?;
        vec!["rest.node", "rest.ele"]
    } else {
        let recorder = Recorder::new(&base)?;
        let surface = recorder
            .rest_surface()
            .context("datasets record cloth and soft tissue only")?;
        weft_mesh::io::write_obj(&out.join("rest.obj"), surface.positions(), surface.faces())?;
        vec!["rest.obj"]
    };
    let mut files = vec![FileEntry {
        path: "scene.toml".into(),
        sha256: sha256_hex(scene_toml.as_bytes()),
    }];
    for f in rest_files {
        files.push(FileEntry {
            path: f.into(),
            sha256: sha256_file(&out.join(f))?,
        });
    }
    let mut manifest = Manifest {
        format: FORMAT.into(),
        dataset: spec.name.clone(),
        size: spec.size,
        seed,
        code_version: code_version.clone(),
        sequences_total: spec.sequences,
        frames_per_sequence: spec.stored_frames(),
        split: spec.split,
        shard,
        files,
        sequences: Vec::new(),
    };
    if manifest_path.exists() {
        ensure!(
            resume,
            "{} already holds this dataset's manifest; pass --resume to continue it, or choose another --out",
            out.display()
        );
        let old: Manifest = read_manifest(&manifest_path)?;
        ensure!(
            old.same_dataset(&manifest) && old.shard == manifest.shard,
            "{} holds a different dataset (name, size, seed, shard or code version differ): {} {} seed {} code {}; \
             refusing to mix them",
            manifest_path.display(),
            old.dataset,
            old.size.as_str(),
            old.seed,
            old.code_version
        );
        // Keep the sequences whose files are intact.
        for s in old.sequences {
            let p = out.join(&s.path);
            if p.exists() && sha256_file(&p)? == s.sha256 {
                manifest.sequences.push(s);
            }
        }
    }
    write_text(&out.join("scene.toml"), &scene_toml)?;
    let todo: Vec<usize> = manifest
        .expected()
        .filter(|i| !manifest.sequences.iter().any(|s| s.index == *i))
        .collect();
    let timing_path = out.join(match shard {
        None => "timing.json".to_string(),
        Some(s) => format!("timing-shard-{}-of-{}.json", s.index, s.count),
    });
    let mut timing: Timing = std::fs::read(&timing_path)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or_default();
    let bar = progress_bar(
        quiet,
        (todo.len() * spec.frames) as u64,
        &format!("{} ({} sequences)", spec.name, todo.len()),
        "frames",
    )?;
    let mut failed = Vec::new();
    for i in todo {
        let wall = Instant::now();
        let rec = if spec.name == drape::NAME {
            drape::chunk(spec, sequence_seed(seed, i), i, &bar)?
        } else if spec.name == nnwarp::NAME {
            let rec = nnwarp::sequence(spec, sequence_seed(seed, i), i)?;
            bar.inc(spec.frames as u64);
            rec
        } else {
            let loaded = LoadedScene {
                scene: spec.sequence_scene(seed, i),
                base_dir: None,
            };
            let mut recorder = Recorder::new(&loaded)?;
            let rec = recorder.record(&spec.name, spec.frames, &bar, |_, _| Ok(()))?;
            let mut metadata = rec.metadata.clone();
            metadata.insert("scene_toml".into(), loaded.scene.to_toml()?);
            StoredSequence {
                arrays: rec.to_arrays(),
                metadata,
                frames: rec.frames(),
                simulated_frames: rec.per_frame.len(),
                solver_seconds: rec.per_frame.iter().map(|f| f.seconds).sum(),
                error: rec.error.clone(),
            }
        };
        let mut meta = rec.metadata.clone();
        meta.insert("sequence".into(), i.to_string());
        let bytes = safetensors_bytes(&rec.arrays, meta)?;
        let path = format!("seq-{i:05}.safetensors");
        write_bytes(&out.join(&path), &bytes)?;
        if let Some(e) = &rec.error {
            failed.push(format!("sequence {i}: {e}"));
        }
        manifest.sequences.push(SequenceEntry {
            index: i,
            seed: sequence_seed(seed, i),
            split: spec.split.of_sequence(i, spec.sequences).into(),
            frames: rec.frames,
            path,
            sha256: sha256_hex(&bytes),
            error: rec.error.clone(),
        });
        manifest.sequences.sort_by_key(|s| s.index);
        write_json(&manifest_path, &manifest)?;
        timing.sequences.insert(
            i,
            (rec.simulated_frames, rec.solver_seconds, wall.elapsed().as_secs_f64()),
        );
        write_json(&timing_path, &timing)?;
    }
    bar.finish_and_clear();
    write_json(&manifest_path, &manifest)?;
    let (frames, wall): (usize, f64) = timing
        .sequences
        .values()
        .fold((0, 0.0), |(f, w), (n, _, s)| (f + n, w + s));
    eprintln!(
        "{}: {} of {} sequences in {} ({:.1} ms per frame) → {}",
        spec.name,
        manifest.sequences.len(),
        manifest.expected().len(),
        manifest_path.display(),
        1e3 * wall / frames.max(1) as f64,
        out.display()
    );
    if !failed.is_empty() {
        return Err(Error::Incomplete(format!(
            "{} sequence(s) stopped early (their frames up to the failure are stored): {}",
            failed.len(),
            failed.join("; ")
        )));
    }
    Ok(manifest)
}

/// Reads and checks a `manifest.json` (or shard manifest).
pub fn read_manifest(path: &Path) -> Result<Manifest> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let m: Manifest =
        serde_json::from_slice(&bytes).with_context(|| format!("{} is not a weft dataset manifest", path.display()))?;
    ensure!(
        m.format == FORMAT,
        "{}: format {:?}, this version reads {FORMAT:?}",
        path.display(),
        m.format
    );
    Ok(m)
}

/// Verifies that every file a manifest lists is present in `dir` with its checksum.
pub fn verify(dir: &Path, m: &Manifest) -> Result<()> {
    let all = m
        .files
        .iter()
        .map(|f| (&f.path, &f.sha256))
        .chain(m.sequences.iter().map(|s| (&s.path, &s.sha256)));
    for (path, sha) in all {
        let p = dir.join(path);
        ensure!(p.exists(), "{} is missing", p.display());
        let got = sha256_file(&p)?;
        if &got != sha {
            return Err(Error::Checksum {
                path: p.display().to_string(),
                expected: sha.clone(),
                actual: got,
            });
        }
    }
    Ok(())
}

/// Joins the shards found in `dirs` into `out`, verifying every checksum; returns the
/// merged manifest (identical to an unsharded run's).
pub fn merge(out: &Path, dirs: &[PathBuf]) -> Result<Manifest> {
    let mut shards: Vec<(PathBuf, Manifest)> = Vec::new();
    for d in dirs {
        let entries = std::fs::read_dir(d).map_err(|e| Error::io(d, e))?;
        let mut names: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("manifest-shard-") && n.ends_with(".json"))
            })
            .collect();
        names.sort();
        ensure!(!names.is_empty(), "{} holds no manifest-shard-*.json", d.display());
        for n in names {
            let m = read_manifest(&n)?;
            verify(d, &m).with_context(|| format!("verifying shard {}", n.display()))?;
            ensure!(
                m.is_complete(),
                "{} is incomplete ({} sequences); finish it with --resume first",
                n.display(),
                m.sequences.len()
            );
            shards.push((d.clone(), m));
        }
    }
    ensure!(!shards.is_empty(), "no shard directory given");
    let first = shards[0].1.clone();
    for (d, m) in &shards {
        ensure!(
            m.same_dataset(&first),
            "{} holds a shard of a different dataset (or code version) than {}",
            d.display(),
            shards[0].0.display()
        );
    }
    let mut merged = Manifest {
        shard: None,
        sequences: Vec::new(),
        ..first.clone()
    };
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let copy = |from: &Path, name: &str| -> Result<()> {
        let (src, to) = (from.join(name), out.join(name));
        if src.canonicalize().map_err(|e| Error::io(&src, e))? != to.canonicalize().unwrap_or_default() {
            write_bytes(&to, &std::fs::read(&src).map_err(|e| Error::io(&src, e))?)?;
        }
        Ok(())
    };
    for f in &first.files {
        copy(&shards[0].0, &f.path)?;
    }
    for (d, m) in &shards {
        for s in &m.sequences {
            ensure!(
                !merged.sequences.iter().any(|t| t.index == s.index),
                "sequence {} appears in more than one shard",
                s.index
            );
            copy(d, &s.path)?;
            merged.sequences.push(s.clone());
        }
    }
    merged.sequences.sort_by_key(|s| s.index);
    let missing: Vec<usize> = (0..merged.sequences_total)
        .filter(|i| !merged.sequences.iter().any(|s| s.index == *i))
        .collect();
    ensure!(
        missing.is_empty(),
        "the shards do not cover sequences {missing:?} of {}",
        merged.sequences_total
    );
    verify(out, &merged)?;
    write_json(&out.join("manifest.json"), &merged)?;
    eprintln!(
        "merged {} shard(s): {} sequences of {}, every checksum verified → {}",
        shards.len(),
        merged.sequences.len(),
        merged.dataset,
        out.display()
    );
    Ok(merged)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_partition_the_sequences() {
        for total in [1, 3, 4, 7, 129] {
            for count in 1..6 {
                let mut all: Vec<usize> = (0..count)
                    .flat_map(|i| Shard { index: i, count }.range(total))
                    .collect();
                all.dedup();
                assert_eq!(all, (0..total).collect::<Vec<_>>(), "{total} in {count}");
            }
        }
        assert!(parse_shard("3/3").is_err() && parse_shard("0/0").is_err() && parse_shard("x").is_err());
        assert_eq!(parse_shard("1/4"), Ok(Shard { index: 1, count: 4 }));
    }

    #[test]
    fn sequence_split_follows_alt_convlstm_proportions_and_keeps_every_part() {
        let n = 129;
        let count = |s| (0..n).filter(|&i| Split::Sequences.of_sequence(i, n) == s).count();
        assert_eq!((count("train"), count("validation"), count("test")), (80, 20, 29));
        let parts: Vec<_> = (0..4).map(|i| Split::Sequences.of_sequence(i, 4)).collect();
        assert_eq!(parts, ["train", "train", "validation", "test"]);
    }

    #[test]
    fn drape_chunks_split_into_geng_sized_training_validation_and_test_sets() {
        for (size, want) in [
            (Size::Quick, (16, 4, 4)),
            (Size::Standard, (1000, 200, 200)),
            (Size::Paper, (8000, 200, 200)),
        ] {
            let spec = DatasetSpec::new(drape::NAME, size).unwrap();
            assert_eq!(
                spec.stored_frames(),
                spec.frames,
                "a drape chunk stores its examples only"
            );
            let n = spec.sequences;
            let examples = |s| (0..n).filter(|&i| spec.split.of_sequence(i, n) == s).count() * spec.frames;
            assert_eq!(
                (examples("train"), examples("validation"), examples("test")),
                want,
                "{size:?}"
            );
            // In index order: every training chunk before every validation chunk before every test chunk.
            let order: Vec<&str> = (0..n).map(|i| spec.split.of_sequence(i, n)).collect();
            let mut sorted = order.clone();
            sorted.sort_by_key(|s| ["train", "validation", "test"].iter().position(|t| t == s));
            assert_eq!(order, sorted);
        }
        // Other datasets store their initial state too.
        assert_eq!(DatasetSpec::new("limb", Size::Quick).unwrap().stored_frames(), 9);
    }

    #[test]
    fn sequence_seeds_differ_across_indices_and_dataset_seeds() {
        let mut seeds: Vec<u64> = (0..100)
            .flat_map(|i| [sequence_seed(0, i), sequence_seed(1, i)])
            .collect();
        seeds.sort();
        seeds.dedup();
        assert_eq!(seeds.len(), 200);
    }
}
