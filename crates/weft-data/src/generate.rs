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
use weft_sim::LoadedScene;

use crate::error::{Context, Error, Result, ensure};
use crate::files::{progress_bar, safetensors_bytes, sha256_file, sha256_hex, write_bytes, write_json, write_text};
use crate::record::Recorder;
use crate::spec::{DatasetSpec, NNWARP, Size, Split, StoredSequence, is_drape, sequence_seed};
use crate::{drape, nnwarp};

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
    /// The revision of what the dataset kind stores ([`revision`]); 0, and absent from
    /// the file, for a kind never revised, so their manifests keep their bytes.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub revision: u32,
    pub sequences_total: usize,
    pub frames_per_sequence: usize,
    pub split: Split,
    pub shard: Option<Shard>,
    pub files: Vec<FileEntry>,
    pub sequences: Vec<SequenceEntry>,
}

const FORMAT: &str = "weft-dataset/1";

fn is_zero(v: &u32) -> bool {
    *v == 0
}

/// The revision of what dataset `name` stores: a change to its generation that makes old
/// sequences a different dataset bumps it, so a resume or merge refuses to mix them and
/// the reader refuses an old one (`nnwarp`: [`crate::nnwarp::REVISION`]).
pub fn revision(name: &str) -> u32 {
    if name == NNWARP { crate::nnwarp::REVISION } else { 0 }
}

impl Manifest {
    /// The sequences that stopped early, one line each: index, frames kept, why.
    pub fn stopped_early(&self) -> Vec<String> {
        self.sequences
            .iter()
            .filter_map(|s| {
                s.error
                    .as_ref()
                    .map(|e| format!("sequence {} stopped early ({} frames kept): {e}", s.index, s.frames))
            })
            .collect()
    }

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
        self.differences(other).is_empty()
    }

    /// What tells this dataset from `other`, each as `field: ours vs theirs` (empty when
    /// they are the same dataset), so a refused resume names what changed.
    fn differences(&self, other: &Manifest) -> Vec<String> {
        let mut out = Vec::new();
        let mut check = |field: &str, a: String, b: String| {
            if a != b {
                out.push(format!("{field}: {a} vs {b}"));
            }
        };
        check("format", self.format.clone(), other.format.clone());
        check("dataset", self.dataset.clone(), other.dataset.clone());
        check("size", self.size.as_str().into(), other.size.as_str().into());
        check("seed", self.seed.to_string(), other.seed.to_string());
        check("code version", self.code_version.clone(), other.code_version.clone());
        check("revision", self.revision.to_string(), other.revision.to_string());
        check(
            "sequences",
            self.sequences_total.to_string(),
            other.sequences_total.to_string(),
        );
        check(
            "stored frames per sequence",
            self.frames_per_sequence.to_string(),
            other.frames_per_sequence.to_string(),
        );
        check("split", format!("{:?}", self.split), format!("{:?}", other.split));
        if self.files != other.files {
            let names = |m: &Manifest| m.files.iter().map(|f| f.path.clone()).collect::<Vec<_>>().join(", ");
            out.push(format!(
                "shared files (scene, rest shape) differ in content: {} vs {}",
                names(self),
                names(other)
            ));
        }
        out
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

/// The most sequences a dataset holds: the paper sizes have hundreds, and the manifest
/// lists every one, so a count far beyond this is a typo that would exhaust memory.
pub const MAX_SEQUENCES: usize = 1_000_000;

/// The most frames a sequence holds (the paper sizes have hundreds); every frame of a
/// sequence is in memory until its file is written.
pub const MAX_FRAMES: usize = 1_000_000;

/// Generates (or resumes) `spec` into `out`; returns the manifest written. A sequence that
/// stops early (a solve that does not converge) keeps its frames up to the failure, and the
/// manifest records why ([`Manifest::stopped_early`]): whether that is acceptable is the
/// caller's decision (the command line fails, an experiment uses the frames and reports
/// them).
pub fn generate(spec: &DatasetSpec, out: &Path, options: &GenerateOptions) -> Result<Manifest> {
    let GenerateOptions {
        shard,
        resume,
        seed,
        quiet,
        ref code_version,
    } = *options;
    ensure!(
        (1..=MAX_SEQUENCES).contains(&spec.sequences),
        "a dataset has 1 to {MAX_SEQUENCES} sequences, got {}",
        spec.sequences
    );
    ensure!(
        (1..=MAX_FRAMES).contains(&spec.frames),
        "a sequence has 1 to {MAX_FRAMES} frames, got {}",
        spec.frames
    );
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
    let rest_files: Vec<&str> = if is_drape(&spec.name) {
        // The sleeve and the body at the neutral pose, and the scene's parameters.
        let scene = weft_sim::scenes::drape::Drape::new(drape::params(&spec.name, spec.size))?;
        let sleeve = scene.sleeve();
        weft_mesh::io::write_obj(&out.join("sleeve.obj"), sleeve.positions(), sleeve.faces())?;
        let body = scene.body_rest();
        weft_mesh::io::write_obj(&out.join("body.obj"), body.positions(), body.faces())?;
        write_json(&out.join("drape.json"), scene.params())?;
        vec!["sleeve.obj", "body.obj", "drape.json"]
    } else if spec.name == NNWARP {
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
        revision: revision(&spec.name),
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
        let mut differences = old.differences(&manifest);
        if old.shard != manifest.shard {
            differences.push(format!("shard: {:?} vs {:?}", old.shard, manifest.shard));
        }
        ensure!(
            differences.is_empty(),
            "{} holds a different dataset ({}, written there vs asked for now); refusing to mix them",
            manifest_path.display(),
            differences.join("; ")
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
    for i in todo {
        let wall = Instant::now();
        let rec = if is_drape(&spec.name) {
            drape::chunk(spec, sequence_seed(seed, i), i, &bar)?
        } else if spec.name == NNWARP {
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
    // The shards' timings joined (the evaluation reads the ground truth's cost from
    // them); a shard without one leaves its sequences out of timing.json.
    let mut timing = Timing::default();
    for (d, m) in &shards {
        if let Some(s) = &m.shard {
            let path = d.join(format!("timing-shard-{}-of-{}.json", s.index, s.count));
            if let Ok(bytes) = std::fs::read(&path) {
                let t: Timing = serde_json::from_slice(&bytes)
                    .with_context(|| format!("{} is not a timing file", path.display()))?;
                timing.sequences.extend(t.sequences);
            }
        }
    }
    if !timing.sequences.is_empty() {
        write_json(&out.join("timing.json"), &timing)?;
    }
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
    fn counts_beyond_the_limits_are_refused_before_anything_is_written() {
        let dir = std::env::temp_dir().join(format!("weft-data-limits-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let base = DatasetSpec::new("sheet-ms-17", Size::Quick).unwrap();
        for (sequences, frames, what) in [
            (0, 2, "sequences"),
            (MAX_SEQUENCES + 1, 2, "sequences"),
            (100_000_000_000, 2, "sequences"),
            (1, 0, "frames"),
            (1, MAX_FRAMES + 1, "frames"),
        ] {
            let spec = DatasetSpec {
                sequences,
                frames,
                ..base.clone()
            };
            let e = generate(&spec, &dir, &GenerateOptions::default()).unwrap_err();
            assert!(matches!(&e, Error::Invalid(m) if m.contains(what)), "{e}");
            assert!(!dir.exists(), "nothing is created for a refused count");
        }
    }

    #[test]
    fn a_refused_resume_names_what_differs() {
        let manifest = |sequences_total, frames_per_sequence, seed| Manifest {
            format: FORMAT.into(),
            dataset: "sheet-ms-17".into(),
            size: Size::Quick,
            seed,
            code_version: "v".into(),
            revision: 0,
            sequences_total,
            frames_per_sequence,
            split: Split::Frames12Of17,
            shard: None,
            files: Vec::new(),
            sequences: Vec::new(),
        };
        let a = manifest(4, 9, 0);
        assert!(a.differences(&manifest(4, 9, 0)).is_empty());
        assert!(a.same_dataset(&manifest(4, 9, 0)));
        // A dataset kind revised since (nnwarp's regime, issue 70) is another dataset.
        let revised = Manifest {
            revision: 2,
            ..manifest(4, 9, 0)
        };
        assert_eq!(a.differences(&revised), vec!["revision: 0 vs 2"]);
        let d = a.differences(&manifest(2, 3, 0));
        assert_eq!(d, vec!["sequences: 4 vs 2", "stored frames per sequence: 9 vs 3"]);
        assert_eq!(a.differences(&manifest(4, 9, 7)), vec!["seed: 0 vs 7"]);
        assert!(!a.same_dataset(&manifest(4, 9, 7)));
    }

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
        for (name, size, want) in [drape::NAME, drape::LOOSE].into_iter().flat_map(|name| {
            [
                (name, Size::Quick, (16, 4, 4)),
                (
                    name,
                    Size::Standard,
                    if name == drape::LOOSE {
                        (600, 100, 100)
                    } else {
                        (1000, 200, 200)
                    },
                ),
                (name, Size::Paper, (8000, 200, 200)),
            ]
        }) {
            let spec = DatasetSpec::new(name, size).unwrap();
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
                "{name} {size:?}"
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

    /// Tan et al. §VI: each SHEET and BALL sequence is its own scene, so the paper size of a
    /// cloth scene is one sequence of 2400 (sheets) or 500 (balls) frames, split 12 in 17.
    #[test]
    fn a_paper_size_cloth_scene_is_one_of_tans_sequences() {
        for (name, frames) in [("sheet-ms", 2400), ("sheet-ms-holes", 2400), ("ball-fem", 500)] {
            let spec = DatasetSpec::new(name, Size::Paper).unwrap();
            assert_eq!((spec.sequences, spec.frames), (1, frames), "{name}");
            assert_eq!(spec.split, Split::Frames12Of17, "{name}");
        }
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
