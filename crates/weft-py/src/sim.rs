//! Scenes simulated on numpy: a built-in scene name or a scene TOML file run through
//! weft-data's recorder, or with a surrogate under weft-sim's guard through weft-data's
//! `simulate_guarded` — the same paths `cargo xtask simulate [--surrogate M]` takes — and
//! the surrogate fitted as `cargo xtask train inertial-correction` fits it.

use std::path::{Path, PathBuf};

use numpy::IntoPyArray;
use numpy::ndarray::Array3;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays;
use crate::errors;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(scene_names, m)?)?;
    m.add_function(wrap_pyfunction!(train_inertial_correction, m)?)?;
    Ok(())
}

/// The built-in scenes' names.
#[pyfunction]
fn scene_names() -> Vec<String> {
    weft_sim::scenes::load::builtin_names().map(String::from).collect()
}

/// Runs `scene` (a built-in name or a TOML file) for `frames` frames (the scene's own
/// count by default; `quick` picks its small variant). Returns a dict: `name`,
/// `positions` `[F + 1, V, 3]` (m; frame 0 is the initial state; the surface for soft
/// tissue), every other recorded array under its name, `faces` (the surface's, over the
/// recorded vertices for cloth and soft tissue; volume scenes give `tets` instead),
/// `seconds` and `error` — `None`, or why the run stopped early (the frames before it
/// are returned).
///
/// With `surrogate` (a model directory) every frame is proposed by it under the guard
/// of `tolerance` (millimetres as text, or `truth`, the default) and `certified`; the
/// dict then holds `name`, `positions`, `faces`, `seconds`, `error` (`None`) and
/// `guard`, the run's record as `guard.json` holds it.
#[pyfunction]
#[pyo3(signature = (scene, frames = None, quick = false, surrogate = None, tolerance = None, certified = false))]
fn simulate<'py>(
    py: Python<'py>,
    scene: &str,
    frames: Option<usize>,
    quick: bool,
    surrogate: Option<PathBuf>,
    tolerance: Option<&str>,
    certified: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let mut loaded = weft_sim::load(scene, quick).map_err(errors::sim)?;
    if let Some(f) = frames {
        loaded.scene.set_frames(f);
    }
    match surrogate {
        Some(dir) => simulate_guarded(py, &loaded, &dir, tolerance, certified),
        None if tolerance.is_some() || certified => Err(pyo3::exceptions::PyValueError::new_err(
            "a guard's tolerance or `certified` needs a surrogate",
        )),
        None => record(py, &loaded),
    }
}

/// The guarded run of [`simulate`]: the settings are checked before the model is read.
fn simulate_guarded<'py>(
    py: Python<'py>,
    loaded: &weft_sim::LoadedScene,
    dir: &Path,
    tolerance: Option<&str>,
    certified: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let settings = weft_data::simulate::guard_settings(tolerance, certified).map_err(errors::data)?;
    let surrogate = weft_surrogate::load_surrogate(dir).map_err(errors::surrogate)?;
    let bar = indicatif::ProgressBar::hidden();
    let rollout = py
        .detach(|| weft_data::simulate::simulate_guarded(loaded, surrogate, settings, &bar))
        .map_err(errors::data)?;
    let v = rollout.rest.num_vertices();
    let out = PyDict::new(py);
    out.set_item("name", &rollout.run.scene)?;
    let positions = Array3::from_shape_vec((rollout.positions.len() / (3 * v), v, 3), rollout.positions)
        .map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))?;
    out.set_item("positions", positions.into_pyarray(py))?;
    out.set_item("faces", arrays::to_indices(py, rollout.rest.faces())?)?;
    out.set_item("seconds", rollout.run.total_seconds)?;
    out.set_item("error", py.None())?;
    let record =
        serde_json::to_value(&rollout.run).map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))?;
    out.set_item("guard", errors::json_to_py(py, &record)?)?;
    Ok(out)
}

/// The unguarded run of [`simulate`], through weft-data's recorder.
fn record<'py>(py: Python<'py>, loaded: &weft_sim::LoadedScene) -> PyResult<Bound<'py, PyDict>> {
    let count = loaded.scene.frames();
    let name = loaded.scene.name().to_string();
    let mut recorder = weft_data::Recorder::new(loaded).map_err(errors::data)?;
    let out = PyDict::new(py);
    match &recorder {
        weft_data::Recorder::Cloth(s) => out.set_item("faces", arrays::to_indices(py, s.mesh().faces())?)?,
        weft_data::Recorder::Volume(s) => out.set_item("tets", arrays::to_indices(py, s.mesh().tets())?)?,
        weft_data::Recorder::SoftTissue(s) => {
            out.set_item("faces", arrays::to_indices(py, s.surface().mesh.faces())?)?
        }
    }
    let bar = indicatif::ProgressBar::hidden();
    let recording = py
        .detach(|| recorder.record(&name, count, &bar, |_, _| Ok(())))
        .map_err(errors::data)?;
    out.set_item("name", &recording.scene)?;
    for (array, width, data) in &recording.arrays {
        let f = data.len() / width.max(&1);
        let a = Array3::from_shape_vec((f, width / 3, 3), data.clone())
            .map_err(|e| pyo3::exceptions::PyValueError::new_err(e.to_string()))?;
        out.set_item(*array, a.into_pyarray(py))?;
    }
    out.set_item("seconds", recording.total_seconds)?;
    out.set_item("error", recording.error.clone())?;
    Ok(out)
}

/// Fits the inertial correction on the cloth dataset in `data` (settings from the JSON
/// file `config`, else the defaults) and writes the model directory `out`, which must not
/// hold a model yet: `cargo xtask train inertial-correction`. Returns the lines that
/// command prints (the chosen ridge weight, the validation and test one-step errors).
#[pyfunction]
#[pyo3(signature = (data, out, config = None))]
fn train_inertial_correction(
    py: Python<'_>,
    data: PathBuf,
    out: PathBuf,
    config: Option<PathBuf>,
) -> PyResult<Vec<String>> {
    py.detach(|| weft_surrogate::fit_directory(&data, &out, config.as_deref()))
        .map_err(errors::surrogate)
}
