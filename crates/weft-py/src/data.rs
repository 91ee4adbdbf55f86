//! Any weft dataset read into numpy arrays, every file checked against the manifest's
//! SHA-256 first (weft-data's `RawDataset`).

use std::path::PathBuf;

use numpy::IntoPyArray;
use numpy::ndarray::{ArrayD, IxDyn};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use weft_data::RawValues;

use crate::errors::{self, json_to_py};

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(load_dataset, m)?)?;
    Ok(())
}

fn array<'py, T: numpy::Element>(py: Python<'py>, shape: &[usize], v: Vec<T>) -> PyResult<Bound<'py, PyAny>> {
    ArrayD::from_shape_vec(IxDyn(shape), v)
        .map(|a| a.into_pyarray(py).into_any())
        .map_err(|e| PyValueError::new_err(e.to_string()))
}

/// The dataset in `path` as a dict: `name`, `manifest` (as written) and `sequences`, a
/// list of dicts with `index`, `split`, `metadata` (values parsed as JSON where they are
/// JSON) and every stored array under its name.
#[pyfunction]
fn load_dataset(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyDict>> {
    let raw = py.detach(|| weft_data::RawDataset::load(&path)).map_err(errors::data)?;
    let out = PyDict::new(py);
    out.set_item("name", &raw.name)?;
    out.set_item("manifest", json_to_py(py, &raw.manifest)?)?;
    let sequences = PyList::empty(py);
    for s in raw.sequences {
        let d = PyDict::new(py);
        d.set_item("index", s.index)?;
        d.set_item("split", &s.split)?;
        let meta = PyDict::new(py);
        for (k, v) in &s.metadata {
            match serde_json::from_str::<serde_json::Value>(v) {
                Ok(j) => meta.set_item(k, json_to_py(py, &j)?)?,
                Err(_) => meta.set_item(k, v)?,
            }
        }
        d.set_item("metadata", meta)?;
        for a in s.arrays {
            let value = match a.values {
                RawValues::F64(v) => array(py, &a.shape, v)?,
                RawValues::F32(v) => array(py, &a.shape, v)?,
                RawValues::I64(v) => array(py, &a.shape, v)?,
                RawValues::U8(v) => array(py, &a.shape, v)?,
            };
            d.set_item(&a.name, value)?;
        }
        sequences.append(d)?;
    }
    out.set_item("sequences", sequences)?;
    Ok(out)
}
