//! Scenes simulated on numpy: a built-in scene name or a scene TOML file run through
//! weft-data's recorder, the same path `cargo xtask simulate` takes.

use numpy::IntoPyArray;
use numpy::ndarray::Array3;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays;
use crate::errors;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(scene_names, m)?)?;
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
#[pyfunction]
#[pyo3(signature = (scene, frames = None, quick = false))]
fn simulate<'py>(py: Python<'py>, scene: &str, frames: Option<usize>, quick: bool) -> PyResult<Bound<'py, PyDict>> {
    let mut loaded = weft_sim::load(scene, quick).map_err(errors::sim)?;
    if let Some(f) = frames {
        loaded.scene.set_frames(f);
    }
    let count = loaded.scene.frames();
    let name = loaded.scene.name().to_string();
    let mut recorder = weft_data::Recorder::new(&loaded).map_err(errors::data)?;
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
