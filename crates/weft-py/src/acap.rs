//! ACAP deformation features and their Poisson inverse on numpy (weft-acap).

use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray3, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use weft_acap::{AcapFeatures, AcapSettings, Feature, PoissonPseudoInverse};

use crate::arrays;
use crate::errors;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Acap>()?;
    Ok(())
}

/// ACAP features of one rest mesh: `encode` deformed frames into 9 numbers per vertex
/// (log-rotation and symmetric stretch), `decode` them back with pinned vertices.
#[pyclass(module = "weft._native", frozen)]
#[derive(Debug)]
pub struct Acap {
    features: AcapFeatures,
}

#[pymethods]
impl Acap {
    #[new]
    fn new(rest_vertices: PyReadonlyArray2<'_, f64>, faces: PyReadonlyArray2<'_, i64>) -> PyResult<Self> {
        let rest = arrays::trimesh(&rest_vertices, &faces)?;
        Ok(Self {
            features: AcapFeatures::new(&rest, AcapSettings::default()).map_err(errors::acap)?,
        })
    }

    #[getter]
    fn num_vertices(&self) -> usize {
        self.features.num_vertices()
    }

    /// Features `[F, V, 9]` of frames `[F, V, 3]` (m): each frame alone (in parallel),
    /// or with `sequence=True` in order, each frame's rotation branches seeded from the
    /// previous frame's so the features stay continuous in time.
    #[pyo3(signature = (frames, sequence = false))]
    fn encode<'py>(
        &self,
        py: Python<'py>,
        frames: PyReadonlyArray3<'py, f64>,
        sequence: bool,
    ) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let v = self.features.num_vertices();
        let frames: Vec<Vec<nalgebra::Vector3<f64>>> = arrays::batch("frames", &frames, v)?
            .into_iter()
            .map(|f| weft_mesh::unflatten(&f))
            .collect();
        let f = frames.len();
        let features = &self.features;
        let out = py
            .detach(|| {
                if sequence {
                    features.encode_sequence(&frames)
                } else {
                    features.encode_batch(&frames)
                }
            })
            .map_err(errors::acap)?;
        let flat: Vec<f64> = out.into_iter().flatten().flatten().collect();
        Array3::from_shape_vec((f, v, 9), flat)
            .map(|a| a.into_pyarray(py))
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// Frames `[F, V, 3]` from features `[F, V, 9]`, with vertices `pins` held at
    /// `pin_positions` `[F, len(pins), 3]` (at least one pin per connected component).
    fn decode<'py>(
        &self,
        py: Python<'py>,
        features: PyReadonlyArray3<'py, f64>,
        pins: Vec<usize>,
        pin_positions: PyReadonlyArray3<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let v = self.features.num_vertices();
        let shape = features.shape();
        if shape[1] != v || shape[2] != 9 {
            return Err(PyValueError::new_err(format!(
                "features: expected shape [F, {v}, 9], got {shape:?}"
            )));
        }
        let feats: Vec<Vec<Feature>> = features
            .as_array()
            .outer_iter()
            .map(|frame| frame.outer_iter().map(|r| std::array::from_fn(|k| r[k])).collect())
            .collect();
        let pinned: Vec<Vec<nalgebra::Vector3<f64>>> = arrays::batch("pin_positions", &pin_positions, pins.len())?
            .into_iter()
            .map(|f| weft_mesh::unflatten(&f))
            .collect();
        if pinned.len() != feats.len() {
            return Err(PyValueError::new_err(format!(
                "pin_positions: {} frames for {} frames of features",
                pinned.len(),
                feats.len()
            )));
        }
        let inverse = PoissonPseudoInverse::new(&self.features, &pins).map_err(errors::acap)?;
        let out = py
            .detach(|| inverse.decode_batch(&feats, &pinned))
            .map_err(errors::acap)?;
        arrays::to_batch(py, out.iter().map(|p| weft_mesh::flatten(p)).collect(), v)
    }
}
