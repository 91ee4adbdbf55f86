//! Reading the pipeline's datasets (`cargo xtask dataset`, layout in docs/DATASETS.md)
//! into f64 frames: the cloth scenes (with Tan et al.'s frame split), `nnwarp`, `limb` and
//! `drape`.
//!
//! A dataset directory holds `manifest.json`, `scene.toml`, `rest.obj` and one
//! `seq-NNNNN.safetensors` per sequence with `positions` `[F, V, 3]`, `controls`
//! `[F, G, 3]` (metres) and `labels` `[F]`. Everything read is checked: shapes against the
//! rest mesh, finiteness, that every sequence names the same grasped vertices, and every
//! file's SHA-256 against the manifest.

use std::path::{Path, PathBuf};

use safetensors::{Dtype, SafeTensors};
use weft_mesh::TriMesh;
use weft_sim::ClothScene;
use weft_sim::scenes::drape::POSE_ANGLES;

use crate::error::{Error, Result};

/// A dataset directory's `manifest.json`, parsed and checked to be a `weft-dataset/1`
/// manifest of `dataset` (any dataset for `None`), and its path.
fn read_manifest(dir: &Path, dataset: Option<&str>) -> Result<(PathBuf, serde_json::Value)> {
    let path = dir.join("manifest.json");
    let text = std::fs::read_to_string(&path).map_err(|e| io_error(&path, e))?;
    let manifest: serde_json::Value = serde_json::from_str(&text).map_err(|e| data_error(&path, e.to_string()))?;
    if manifest["format"] != "weft-dataset/1" || dataset.is_some_and(|d| manifest["dataset"] != d) {
        let what = dataset.map_or(String::new(), |d| format!(" {d}"));
        return Err(data_error(&path, format!("not a weft-dataset/1{what} manifest")));
    }
    // The files every sequence shares (scene, rest shape) are verified up front.
    for (k, entry) in manifest["files"].as_array().into_iter().flatten().enumerate() {
        let rel = entry["path"]
            .as_str()
            .ok_or_else(|| data_error(&path, format!("file entry {k} has no path")))?;
        let file = dir.join(rel);
        let bytes = std::fs::read(&file).map_err(|e| io_error(&file, e))?;
        verify_checksum(&file, &bytes, &entry["sha256"])?;
    }
    Ok((path, manifest))
}

/// Checks `bytes` (read from `path`) against the manifest's SHA-256 `expected`: a dataset
/// file changed after it was written (a flipped byte, a truncated copy) is refused by
/// name before anything trains on it.
fn verify_checksum(path: &Path, bytes: &[u8], expected: &serde_json::Value) -> Result<()> {
    use sha2::Digest;
    let expected = expected
        .as_str()
        .ok_or_else(|| data_error(path, "the manifest lists no sha256 for it"))?;
    let actual: String = sha2::Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect();
    if actual != expected {
        return Err(Error::Checksum {
            path: path.display().to_string(),
            expected: expected.to_string(),
            actual,
        });
    }
    Ok(())
}

/// One file the manifest lists (a sequence, or a chunk of examples), opened.
struct Listed<'a> {
    /// Its position in the dataset (the manifest's `index`).
    index: usize,
    /// `train`, `validation` or `test`.
    split: &'a str,
    path: PathBuf,
    tensors: SafeTensors<'a>,
    /// The file's string metadata (empty when it has none).
    metadata: std::collections::HashMap<String, String>,
}

impl Listed<'_> {
    /// Metadata entry `key`, parsed as JSON.
    fn meta<T: serde::de::DeserializeOwned>(&self, key: &str) -> Result<T> {
        let text = self
            .metadata
            .get(key)
            .ok_or_else(|| data_error(&self.path, format!("metadata lacks {key}")))?;
        serde_json::from_str(text).map_err(|e| data_error(&self.path, format!("metadata {key}: {e}")))
    }
}

/// Calls `each` on every file `manifest` lists in `dir`, in order, one file in memory at a
/// time.
fn for_each_listed(
    dir: &Path,
    manifest_path: &Path,
    manifest: &serde_json::Value,
    mut each: impl FnMut(Listed<'_>) -> Result<()>,
) -> Result<()> {
    let listed = manifest["sequences"]
        .as_array()
        .ok_or_else(|| data_error(manifest_path, "no sequence list"))?;
    for (k, entry) in listed.iter().enumerate() {
        let rel = entry["path"]
            .as_str()
            .ok_or_else(|| data_error(manifest_path, format!("entry {k} has no path")))?;
        let path = dir.join(rel);
        let bytes = std::fs::read(&path).map_err(|e| io_error(&path, e))?;
        verify_checksum(&path, &bytes, &entry["sha256"])?;
        let tensors = SafeTensors::deserialize(&bytes).map_err(|e| data_error(&path, e.to_string()))?;
        let (_, meta) = SafeTensors::read_metadata(&bytes).map_err(|e| data_error(&path, e.to_string()))?;
        each(Listed {
            index: entry["index"].as_u64().map_or(k, |i| i as usize),
            split: entry["split"].as_str().unwrap_or("train"),
            metadata: meta.metadata().clone().unwrap_or_default(),
            path,
            tensors,
        })?;
    }
    Ok(())
}

/// Tan et al. §VI-A: of every 17 consecutive frames the first 12 train and the other 5
/// test. `m` counts from a sequence's first frame.
pub fn is_train_frame(m: usize) -> bool {
    m % 17 < 12
}

/// Validation frames, carved from Tan et al.'s training frames (they had no validation
/// split): the last two of every twelve (`m mod 17` ∈ {10, 11}). They are never trained
/// on, so model selection reads frames neither the loss nor the test split sees.
pub fn is_validation_frame(m: usize) -> bool {
    matches!(m % 17, 10 | 11)
}

/// One simulated sequence.
#[derive(Debug, Clone)]
pub struct ClothSequence {
    /// Its index in the dataset.
    pub index: usize,
    /// `[F, V, 3]` flat, metres; frame 0 is the initial state.
    pub positions: Vec<f64>,
    /// `[F, G, 3]` flat: the grasped vertices' prescribed positions `q_m`.
    pub controls: Vec<f64>,
    /// Motion label code per frame (`weft_sim::MotionLabel`).
    pub labels: Vec<u8>,
    num_vertices: usize,
    num_grasped: usize,
}

impl ClothSequence {
    /// A sequence from its arrays (`F` frames of `V` vertices, `G` grasped), e.g. simulated
    /// in memory; the lengths must agree.
    pub fn new(
        index: usize,
        positions: Vec<f64>,
        controls: Vec<f64>,
        labels: Vec<u8>,
        num_vertices: usize,
        num_grasped: usize,
    ) -> Result<Self> {
        let f = labels.len();
        if positions.len() != 3 * num_vertices * f || controls.len() != 3 * num_grasped * f {
            return Err(Error::Shape {
                what: "cloth sequence",
                expected: format!("{f} frames of {num_vertices} positions and {num_grasped} controls"),
                got: format!("{} position and {} control values", positions.len(), controls.len()),
            });
        }
        Ok(Self {
            index,
            positions,
            controls,
            labels,
            num_vertices,
            num_grasped,
        })
    }

    pub fn num_frames(&self) -> usize {
        self.labels.len()
    }

    /// Frame `m`'s positions, `3V` values.
    pub fn frame(&self, m: usize) -> &[f64] {
        let n = 3 * self.num_vertices;
        &self.positions[m * n..(m + 1) * n]
    }

    /// Frame `m`'s controls, `3G` values.
    pub fn control(&self, m: usize) -> &[f64] {
        let n = 3 * self.num_grasped;
        &self.controls[m * n..(m + 1) * n]
    }
}

/// A cloth dataset in memory.
#[derive(Debug, Clone)]
pub struct ClothDataset {
    pub dir: PathBuf,
    /// The dataset's name (`manifest.json`).
    pub name: String,
    /// The scene before per-sequence seeding (`scene.toml`); its energies, masses and Δt
    /// are those of every sequence.
    pub scene: ClothScene,
    pub rest: TriMesh,
    pub grasp: Vec<usize>,
    pub sequences: Vec<ClothSequence>,
}

impl ClothDataset {
    /// One sequence of `frames` frames of `scene` (its initial state and `frames − 1`
    /// steps) simulated in memory, with each frame's controls and motion label: a dataset
    /// for tests, benchmarks and quick experiments that needs no directory (`dir` is the
    /// temporary directory). Stops at the first step whose solve fails, with its error.
    pub fn simulate(name: &str, scene: ClothScene, frames: usize) -> Result<Self> {
        if frames == 0 {
            return Err(Error::Shape {
                what: "simulated cloth sequence",
                expected: "at least one frame".into(),
                got: "0".into(),
            });
        }
        let mut sim = weft_sim::ClothSimulation::new(scene.clone(), None)?;
        let rest = sim.mesh().clone();
        let grasp = sim.grasp_vertices().to_vec();
        let mut positions = sim.integrator().positions().to_vec();
        let (mut controls, mut labels) = (Vec::new(), Vec::new());
        for m in 0..frames {
            let (q, label) = sim.controls_at(m);
            controls.extend(q.iter().flat_map(|p| [p.x, p.y, p.z]));
            labels.push(label.code());
            if m + 1 < frames {
                positions.extend(sim.step()?.positions);
            }
        }
        let sequence = ClothSequence::new(0, positions, controls, labels, rest.num_vertices(), grasp.len())?;
        Ok(Self {
            dir: std::env::temp_dir(),
            name: name.into(),
            scene,
            rest,
            grasp,
            sequences: vec![sequence],
        })
    }

    /// Frame `m` of sequence `s`'s grasp as prescribed DOFs `(dof, value)` (m), as the
    /// integrator takes them: what replays a stored sequence step by step.
    pub fn prescribed_at(&self, s: usize, m: usize) -> Vec<(usize, f64)> {
        let q = self.sequences[s].control(m);
        self.grasp
            .iter()
            .enumerate()
            .flat_map(|(g, &v)| (0..3).map(move |k| (3 * v + k, q[3 * g + k])))
            .collect()
    }

    /// `frame` (`3V` values, metres) with its grasped vertices moved to the control
    /// positions `q` (`3G` values in the order of [`ClothDataset::grasp`]): the
    /// configuration at which a method's frame is judged against the controls it was given.
    pub fn with_grasp_at(&self, frame: &[f64], q: &[f64]) -> Result<Vec<f64>> {
        let v = self.rest.num_vertices();
        if frame.len() != 3 * v || q.len() != 3 * self.grasp.len() {
            return Err(Error::Shape {
                what: "frame and grasp controls",
                expected: format!("{} positions and {} controls", 3 * v, 3 * self.grasp.len()),
                got: format!("{} and {}", frame.len(), q.len()),
            });
        }
        let mut out = frame.to_vec();
        for (k, &g) in self.grasp.iter().enumerate() {
            out[3 * g..3 * g + 3].copy_from_slice(&q[3 * k..3 * k + 3]);
        }
        Ok(out)
    }
}

fn io_error(path: &Path, source: std::io::Error) -> Error {
    Error::Io {
        path: path.display().to_string(),
        source,
    }
}

fn data_error(path: &Path, reason: impl Into<String>) -> Error {
    Error::Dataset {
        path: path.display().to_string(),
        reason: reason.into(),
    }
}

fn f64_array(path: &Path, st: &SafeTensors, name: &str, shape_tail: &[usize]) -> Result<(usize, Vec<f64>)> {
    let t = st
        .tensor(name)
        .map_err(|e| data_error(path, format!("array {name}: {e}")))?;
    if t.dtype() != Dtype::F64 || t.shape().len() != 1 + shape_tail.len() || t.shape()[1..] != *shape_tail {
        return Err(data_error(
            path,
            format!(
                "array {name} is {:?} {:?}, expected F64 [F, {shape_tail:?}]",
                t.dtype(),
                t.shape()
            ),
        ));
    }
    let v: Vec<f64> = t
        .data()
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")))
        .collect();
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(data_error(path, format!("array {name} has a non-finite value at {i}")));
    }
    Ok((t.shape()[0], v))
}

impl ClothDataset {
    /// Reads the dataset in `dir` (every sequence listed in its manifest).
    pub fn load(dir: &Path) -> Result<Self> {
        let (manifest_path, manifest) = read_manifest(dir, None)?;
        let name = manifest["dataset"].as_str().unwrap_or_default().to_string();
        let other_kind = if crate::spec::is_drape(&name) {
            Some("a drape one (for `train drape`)")
        } else if name == crate::spec::NNWARP {
            Some("a volumetric one (for `train nnwarp`)")
        } else if weft_sim::scenes::load::SOFT_TISSUE_SCENES.contains(&name.as_str()) {
            Some("a soft-tissue one (for `train altconv`)")
        } else {
            None
        };
        if let Some(kind) = other_kind {
            return Err(data_error(
                &manifest_path,
                format!("holds dataset {name:?}, {kind}, not a cloth dataset"),
            ));
        }
        let scene_path = dir.join("scene.toml");
        let scene_text = std::fs::read_to_string(&scene_path).map_err(|e| io_error(&scene_path, e))?;
        let scene = ClothScene::from_toml(&scene_text).map_err(|e| data_error(&scene_path, e.to_string()))?;
        let rest_path = dir.join("rest.obj");
        let rest = weft_mesh::io::read_obj(&rest_path).map_err(|e| data_error(&rest_path, e.to_string()))?;
        let v = rest.num_vertices();
        let mut grasp: Option<Vec<usize>> = None;
        let mut sequences = Vec::new();
        for_each_listed(dir, &manifest_path, &manifest, |file| {
            let path = &file.path;
            let g: Vec<usize> = file.meta("grasp_vertices")?;
            if g.iter().any(|&i| i >= v) {
                return Err(data_error(path, "a grasped vertex is outside the rest mesh"));
            }
            match &grasp {
                Some(prev) if *prev != g => return Err(data_error(path, "grasped vertices differ between sequences")),
                _ => grasp = Some(g.clone()),
            }
            let st = &file.tensors;
            let (frames, positions) = f64_array(path, st, "positions", &[v, 3])?;
            let (cf, controls) = f64_array(path, st, "controls", &[g.len(), 3])?;
            let labels = st
                .tensor("labels")
                .map_err(|e| data_error(path, format!("array labels: {e}")))?
                .data()
                .to_vec();
            if cf != frames || labels.len() != frames {
                return Err(data_error(
                    path,
                    "positions, controls and labels disagree on the frame count",
                ));
            }
            sequences.push(ClothSequence {
                index: file.index,
                positions,
                controls,
                labels,
                num_vertices: v,
                num_grasped: g.len(),
            });
            Ok(())
        })?;
        Ok(Self {
            dir: dir.to_path_buf(),
            name,
            scene,
            rest,
            grasp: grasp.ok_or_else(|| data_error(&manifest_path, "the dataset has no sequence"))?,
            sequences,
        })
    }
}

/// The values of one stored array, in its file's element type.
#[derive(Debug, Clone, PartialEq)]
pub enum RawValues {
    F64(Vec<f64>),
    F32(Vec<f32>),
    I64(Vec<i64>),
    U8(Vec<u8>),
}

/// One array of a sequence file: its name, shape and values (row-major).
#[derive(Debug, Clone, PartialEq)]
pub struct RawArray {
    pub name: String,
    pub shape: Vec<usize>,
    pub values: RawValues,
}

/// One sequence file of any dataset, as stored.
#[derive(Debug, Clone)]
pub struct RawSequence {
    pub index: usize,
    /// `train`, `validation` or `test`.
    pub split: String,
    /// The file's string metadata (JSON values as text).
    pub metadata: std::collections::HashMap<String, String>,
    /// Its arrays in name order.
    pub arrays: Vec<RawArray>,
}

/// Any weft dataset read without interpreting its arrays: what a reader in another
/// language needs (the Python package's `weft.datasets.load`). Every file is checked
/// against the manifest's SHA-256 first, as the typed readers do.
#[derive(Debug, Clone)]
pub struct RawDataset {
    pub dir: PathBuf,
    /// The manifest's `dataset`.
    pub name: String,
    /// `manifest.json` as written.
    pub manifest: serde_json::Value,
    pub sequences: Vec<RawSequence>,
}

impl RawDataset {
    /// Reads every sequence of the dataset in `dir` (checksums verified).
    pub fn load(dir: &Path) -> Result<Self> {
        let (manifest_path, manifest) = read_manifest(dir, None)?;
        let mut sequences = Vec::new();
        for_each_listed(dir, &manifest_path, &manifest, |file| {
            let mut arrays = Vec::new();
            let mut tensors = file.tensors.tensors();
            tensors.sort_by(|a, b| a.0.cmp(&b.0));
            for (name, view) in tensors {
                let bytes = view.data();
                let values = match view.dtype() {
                    safetensors::Dtype::F64 => RawValues::F64(
                        bytes
                            .chunks_exact(8)
                            .map(|b| f64::from_le_bytes(b.try_into().unwrap_or_default()))
                            .collect(),
                    ),
                    safetensors::Dtype::F32 => RawValues::F32(
                        bytes
                            .chunks_exact(4)
                            .map(|b| f32::from_le_bytes(b.try_into().unwrap_or_default()))
                            .collect(),
                    ),
                    safetensors::Dtype::I64 => RawValues::I64(
                        bytes
                            .chunks_exact(8)
                            .map(|b| i64::from_le_bytes(b.try_into().unwrap_or_default()))
                            .collect(),
                    ),
                    safetensors::Dtype::U8 => RawValues::U8(bytes.to_vec()),
                    other => {
                        return Err(data_error(
                            &file.path,
                            format!("array {name} has element type {other:?}, which weft does not write"),
                        ));
                    }
                };
                arrays.push(RawArray {
                    name,
                    shape: view.shape().to_vec(),
                    values,
                });
            }
            sequences.push(RawSequence {
                index: file.index,
                split: file.split.to_string(),
                metadata: file.metadata.clone(),
                arrays,
            });
            Ok(())
        })?;
        Ok(Self {
            dir: dir.to_path_buf(),
            name: manifest["dataset"].as_str().unwrap_or_default().to_string(),
            manifest,
            sequences,
        })
    }
}

/// One sequence of the `nnwarp` dataset: the field that drove it, its Poisson ratio, and
/// per frame the linear and one material's registered displacements (unit-sphere units).
#[derive(Debug, Clone)]
pub struct WarpSequence {
    pub index: usize,
    /// `train`, `validation` or `test` (the manifest's split of whole sequences).
    pub split: String,
    pub field: weft_sim::warp::FieldDirection,
    pub poisson: f64,
    /// `linear[f]`, `nonlinear[f]`: flat `3V` displacements of frame `f`.
    pub linear: Vec<Vec<f64>>,
    pub nonlinear: Vec<Vec<f64>>,
}

/// The `nnwarp` dataset for one material (NNWarp §5; docs/DATASETS.md).
#[derive(Debug, Clone)]
pub struct WarpDataset {
    pub dir: PathBuf,
    /// The training beam scaled into the unit sphere (`rest.node`/`rest.ele`).
    pub body: weft_mesh::TetMesh,
    pub anchors: Vec<usize>,
    /// The array name of the material (`co-rotational`, `stvk`, `neo-hookean`).
    pub material: String,
    pub sequences: Vec<WarpSequence>,
    /// The material's registered frames left out because they are off the branch their
    /// sequence started on (the sequences' `off_branch` metadata; docs/DATASETS.md).
    pub dropped_frames: usize,
}

fn vec3_of(path: &Path, v: &serde_json::Value, key: &str) -> Result<nalgebra::Vector3<f64>> {
    let a: Vec<f64> =
        serde_json::from_value(v[key].clone()).map_err(|e| data_error(path, format!("field {key}: {e}")))?;
    if a.len() != 3 {
        return Err(data_error(path, format!("field {key} has {} components", a.len())));
    }
    Ok(nalgebra::Vector3::new(a[0], a[1], a[2]))
}

impl WarpDataset {
    /// Reads every sequence of the dataset in `dir`, keeping `material`'s registration.
    pub fn load(dir: &Path, material: &str) -> Result<Self> {
        let (manifest_path, manifest) = read_manifest(dir, Some("nnwarp"))?;
        let revision = manifest["revision"].as_u64().unwrap_or(0);
        if revision != u64::from(crate::nnwarp::REVISION) {
            return Err(data_error(
                &manifest_path,
                format!(
                    "holds nnwarp revision {revision}, this version reads {} (its linear frames were solved under \
                     plain loads, not the runtime's; regenerate it)",
                    crate::nnwarp::REVISION
                ),
            ));
        }
        let rest_path = dir.join("rest.node");
        let body = weft_mesh::io::read_tetgen(&rest_path).map_err(|e| data_error(&rest_path, e.to_string()))?;
        let v = body.num_vertices();
        let mut anchors: Option<Vec<usize>> = None;
        let mut sequences = Vec::new();
        let mut dropped_frames = 0;
        for_each_listed(dir, &manifest_path, &manifest, |file| {
            let path = &file.path;
            let a: Vec<usize> = file.meta("anchors")?;
            if a.iter().any(|&i| i >= v) {
                return Err(data_error(path, "an anchor is outside the body"));
            }
            match &anchors {
                Some(prev) if *prev != a => return Err(data_error(path, "anchors differ between sequences")),
                _ => anchors = Some(a),
            }
            let field: serde_json::Value = file.meta("field")?;
            let field = match field["kind"].as_str() {
                Some("directional") => weft_sim::warp::FieldDirection::Directional(vec3_of(path, &field, "direction")?),
                Some("circular") => weft_sim::warp::FieldDirection::Circular {
                    center: vec3_of(path, &field, "center")?,
                    axis: vec3_of(path, &field, "axis")?,
                },
                _ => return Err(data_error(path, "field kind is neither directional nor circular")),
            };
            let poisson: f64 = file.meta("poisson")?;
            let (f, linear) = f64_array(path, &file.tensors, "linear", &[v, 3])?;
            let (fm, nonlinear) = f64_array(path, &file.tensors, material, &[v, 3])?;
            if f != fm {
                return Err(data_error(path, "linear and registered frames disagree in number"));
            }
            let split = |x: Vec<f64>| x.chunks_exact(3 * v).map(<[f64]>::to_vec).collect::<Vec<_>>();
            let (mut linear, mut nonlinear) = (split(linear), split(nonlinear));
            // The material's frames from the first one off the branch on are dropped.
            let off: serde_json::Value = file.meta("off_branch")?;
            if let Some(k) = off[material]["frame"].as_u64() {
                let keep = (k as usize).min(f);
                dropped_frames += f - keep;
                linear.truncate(keep);
                nonlinear.truncate(keep);
            }
            sequences.push(WarpSequence {
                index: file.index,
                split: file.split.to_string(),
                field,
                poisson,
                linear,
                nonlinear,
            });
            Ok(())
        })?;
        Ok(Self {
            dir: dir.to_path_buf(),
            body,
            anchors: anchors.ok_or_else(|| data_error(&manifest_path, "the dataset has no sequence"))?,
            material: material.to_string(),
            sequences,
            dropped_frames,
        })
    }

    /// The number of training sequences.
    pub fn training_count(&self) -> usize {
        self.sequences.iter().filter(|s| s.split == "train").count()
    }

    /// This dataset with only its first `k` training sequences (in index order); the
    /// validation and test splits are kept whole. Data-size studies train on these
    /// prefixes: each is a subset of the next larger one and depends on nothing but `k`,
    /// so a curve over growing `k` measures what more data buys and nothing else.
    /// `k` beyond the training count keeps all of them.
    pub fn with_training_prefix(&self, k: usize) -> Self {
        let mut order: Vec<&WarpSequence> = self.sequences.iter().collect();
        order.sort_by_key(|s| s.index);
        let mut taken = 0;
        let sequences = order
            .into_iter()
            .filter(|s| {
                if s.split != "train" {
                    return true;
                }
                taken += 1;
                taken <= k
            })
            .cloned()
            .collect();
        Self {
            sequences,
            ..self.clone()
        }
    }
}

/// One sequence of the `limb` soft-tissue dataset (design §6): per frame the skinned
/// surface `X_t` and the simulated tissue surface `Y_t`, flat `3V` (metres).
#[derive(Debug, Clone)]
pub struct LimbSequence {
    pub index: usize,
    /// `train`, `validation` or `test` (the manifest's split of whole sequences).
    pub split: String,
    pub skinned: Vec<Vec<f64>>,
    pub simulated: Vec<Vec<f64>>,
}

/// The `limb` dataset: the rest surface and every sequence (docs/DATASETS.md).
#[derive(Debug, Clone)]
pub struct LimbDataset {
    pub dir: PathBuf,
    /// The dataset's name: `limb` or `limb-jiggle`.
    pub name: String,
    /// The body's surface at rest (`rest.obj`); all frames are in its vertex order.
    pub rest: TriMesh,
    pub sequences: Vec<LimbSequence>,
}

impl LimbDataset {
    /// Reads every sequence of a soft-tissue dataset (`limb` or `limb-jiggle`) in `dir`.
    pub fn load(dir: &Path) -> Result<Self> {
        let (manifest_path, manifest) = read_manifest(dir, None)?;
        let name = manifest["dataset"].as_str().unwrap_or_default().to_string();
        if !weft_sim::scenes::load::SOFT_TISSUE_SCENES.contains(&name.as_str()) {
            return Err(data_error(
                &manifest_path,
                format!("holds dataset {name:?}, not a soft-tissue one (limb, limb-jiggle)"),
            ));
        }
        let rest_path = dir.join("rest.obj");
        let rest = weft_mesh::io::read_obj(&rest_path).map_err(|e| data_error(&rest_path, e.to_string()))?;
        let v = rest.num_vertices();
        let mut sequences = Vec::new();
        for_each_listed(dir, &manifest_path, &manifest, |file| {
            let path = &file.path;
            let (f, skinned) = f64_array(path, &file.tensors, "skinned", &[v, 3])?;
            let (fs, simulated) = f64_array(path, &file.tensors, "simulated", &[v, 3])?;
            if f != fs || f < 2 {
                return Err(data_error(
                    path,
                    "skinned and simulated frames disagree, or fewer than two",
                ));
            }
            let frames = |x: Vec<f64>| x.chunks_exact(3 * v).map(<[f64]>::to_vec).collect::<Vec<_>>();
            sequences.push(LimbSequence {
                index: file.index,
                split: file.split.to_string(),
                skinned: frames(skinned),
                simulated: frames(simulated),
            });
            Ok(())
        })?;
        if sequences.is_empty() {
            return Err(data_error(&manifest_path, "the dataset has no sequence"));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            name,
            rest,
            sequences,
        })
    }

    /// The sequences of one split.
    pub fn split<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a LimbSequence> + 'a {
        self.sequences.iter().filter(move |s| s.split == name)
    }
}

/// One example of the `drape` dataset (design §8): the pose and the sleeve's kinematic
/// guess and draped truth, flat `3V` (metres).
#[derive(Debug, Clone)]
pub struct DrapeExample {
    /// `train`, `validation` or `test` (the split of its chunk).
    pub split: String,
    /// Shoulder flexion, shoulder abduction, shoulder twist, elbow flexion (rad).
    pub pose: [f64; POSE_ANGLES],
    pub guess: Vec<f64>,
    pub truth: Vec<f64>,
}

/// The `drape` dataset: the rest sleeve and body and every example (docs/DATASETS.md).
#[derive(Debug, Clone)]
pub struct DrapeDataset {
    pub dir: PathBuf,
    /// `drape` or `drape-loose`.
    pub name: String,
    /// The sleeve at rest (`sleeve.obj`); every example is in its vertex order.
    pub sleeve: TriMesh,
    /// The body at the neutral pose (`body.obj`).
    pub body: TriMesh,
    pub examples: Vec<DrapeExample>,
}

impl DrapeDataset {
    /// Reads every chunk of the `drape` or `drape-loose` dataset in `dir`.
    pub fn load(dir: &Path) -> Result<Self> {
        let (manifest_path, manifest) = read_manifest(dir, None)?;
        let name = manifest["dataset"].as_str().unwrap_or_default().to_string();
        if !crate::spec::is_drape(&name) {
            return Err(data_error(
                &manifest_path,
                format!("holds dataset {name:?}, not a drape one (drape, drape-loose)"),
            ));
        }
        let read = |name: &str| -> Result<TriMesh> {
            let p = dir.join(name);
            weft_mesh::io::read_obj(&p).map_err(|e| data_error(&p, e.to_string()))
        };
        let (sleeve, body) = (read("sleeve.obj")?, read("body.obj")?);
        let v = sleeve.num_vertices();
        let mut examples = Vec::new();
        for_each_listed(dir, &manifest_path, &manifest, |file| {
            let path = &file.path;
            let (f, pose) = f64_array(path, &file.tensors, "pose", &[POSE_ANGLES])?;
            let (fg, guess) = f64_array(path, &file.tensors, "guess", &[v, 3])?;
            let (ft, truth) = f64_array(path, &file.tensors, "truth", &[v, 3])?;
            if f != fg || f != ft {
                return Err(data_error(
                    path,
                    "pose, guess and truth hold different numbers of examples",
                ));
            }
            for k in 0..f {
                examples.push(DrapeExample {
                    split: file.split.to_string(),
                    pose: std::array::from_fn(|i| pose[POSE_ANGLES * k + i]),
                    guess: guess[3 * v * k..3 * v * (k + 1)].to_vec(),
                    truth: truth[3 * v * k..3 * v * (k + 1)].to_vec(),
                });
            }
            Ok(())
        })?;
        if examples.is_empty() {
            return Err(data_error(&manifest_path, "the dataset has no example"));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            name,
            sleeve,
            body,
            examples,
        })
    }

    /// The examples of one split.
    pub fn split<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a DrapeExample> + 'a {
        self.examples.iter().filter(move |e| e.split == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cloth_reader_given_another_kind_of_dataset_names_its_kind() {
        let dir = std::env::temp_dir().join(format!("weft-data-kind-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (name, kind) in [
            ("nnwarp", "volumetric"),
            ("drape-loose", "drape"),
            ("limb-jiggle", "soft-tissue"),
        ] {
            let manifest = serde_json::json!({"format": "weft-dataset/1", "dataset": name, "files": []});
            std::fs::write(dir.join("manifest.json"), manifest.to_string()).unwrap();
            let e = ClothDataset::load(&dir).unwrap_err().to_string();
            assert!(e.contains(kind) && e.contains("not a cloth dataset"), "{name}: {e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    fn sequence(index: usize, split: &str) -> WarpSequence {
        WarpSequence {
            index,
            split: split.into(),
            field: weft_sim::warp::FieldDirection::Directional(nalgebra::Vector3::y()),
            poisson: 0.3,
            linear: vec![vec![index as f64]],
            nonlinear: vec![vec![-(index as f64)]],
        }
    }

    fn dataset(order: &[usize]) -> WarpDataset {
        let splits = [
            "train",
            "train",
            "validation",
            "train",
            "test",
            "train",
            "train",
            "validation",
        ];
        let body = weft_mesh::generators::beam(&weft_mesh::generators::BeamParams {
            cells: [1, 1, 1],
            size: [1.0, 1.0, 1.0],
        })
        .unwrap();
        WarpDataset {
            dir: PathBuf::from("mem"),
            body,
            anchors: vec![0],
            material: "stvk".into(),
            sequences: order.iter().map(|&i| sequence(i, splits[i])).collect(),
            dropped_frames: 0,
        }
    }

    fn indices(d: &WarpDataset, split: &str) -> Vec<usize> {
        let mut v: Vec<usize> = d
            .sequences
            .iter()
            .filter(|s| s.split == split)
            .map(|s| s.index)
            .collect();
        v.sort_unstable();
        v
    }

    #[test]
    fn training_prefixes_are_nested_deterministic_and_keep_the_other_splits() {
        let full = dataset(&[0, 1, 2, 3, 4, 5, 6, 7]);
        // The order sequences were read in (shards, merges) does not change a prefix.
        let shuffled = dataset(&[5, 2, 7, 0, 3, 6, 1, 4]);
        assert_eq!(full.training_count(), 5);
        let mut previous: Vec<usize> = Vec::new();
        for k in 0..=6 {
            let a = full.with_training_prefix(k);
            let b = shuffled.with_training_prefix(k);
            let train = indices(&a, "train");
            assert_eq!(train, indices(&b, "train"), "k = {k}");
            assert_eq!(train.len(), k.min(5));
            assert!(previous.iter().all(|i| train.contains(i)), "k = {k}: not nested");
            assert_eq!(train, [0, 1, 3, 5, 6][..k.min(5)]);
            assert_eq!(indices(&a, "validation"), [2, 7]);
            assert_eq!(indices(&a, "test"), [4]);
            // The frames travel with their sequence.
            assert!(a.sequences.iter().all(|s| s.linear[0][0] == s.index as f64));
            previous = train;
        }
    }
}
