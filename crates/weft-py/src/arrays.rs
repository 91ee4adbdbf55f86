//! numpy arrays in and out, with the shapes checked before anything runs.

use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// A `[B, V, 3]` float64 array as `B` flat `3V` vectors (copied: solves run without the
/// GIL, and numpy memory must not be read then).
pub fn batch(what: &str, a: &PyReadonlyArray3<'_, f64>, vertices: usize) -> PyResult<Vec<Vec<f64>>> {
    let shape = a.shape();
    if shape[1] != vertices || shape[2] != 3 {
        return Err(PyValueError::new_err(format!(
            "{what}: expected shape [B, {vertices}, 3], got {shape:?}"
        )));
    }
    let view = a.as_array();
    Ok(view
        .outer_iter()
        .map(|example| example.iter().copied().collect())
        .collect())
}

/// A `[V, 3]` float64 array as positions.
pub fn points(what: &str, a: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<nalgebra::Vector3<f64>>> {
    let shape = a.shape();
    if shape[1] != 3 || shape[0] == 0 {
        return Err(PyValueError::new_err(format!(
            "{what}: expected shape [V, 3], got {shape:?}"
        )));
    }
    Ok(a.as_array()
        .outer_iter()
        .map(|r| nalgebra::Vector3::new(r[0], r[1], r[2]))
        .collect())
}

/// A `[F, 3]` int64 array as triangles (indices checked non-negative here, in range by
/// the mesh).
pub fn triangles(a: &PyReadonlyArray2<'_, i64>) -> PyResult<Vec<[usize; 3]>> {
    let shape = a.shape();
    if shape[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "faces: expected shape [F, 3], got {shape:?}"
        )));
    }
    a.as_array()
        .outer_iter()
        .enumerate()
        .map(|(f, r)| {
            let mut t = [0usize; 3];
            for k in 0..3 {
                t[k] = usize::try_from(r[k])
                    .map_err(|_| PyValueError::new_err(format!("faces: face {f} has a negative index {}", r[k])))?;
            }
            Ok(t)
        })
        .collect()
}

/// A mesh from numpy vertices and faces.
pub fn trimesh(
    vertices: &PyReadonlyArray2<'_, f64>,
    faces: &PyReadonlyArray2<'_, i64>,
) -> PyResult<weft_mesh::TriMesh> {
    weft_mesh::TriMesh::new(points("rest_vertices", vertices)?, triangles(faces)?).map_err(crate::errors::mesh)
}

/// `B` flat `3V` vectors as a `[B, V, 3]` array.
pub fn to_batch<'py>(py: Python<'py>, rows: Vec<Vec<f64>>, vertices: usize) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let b = rows.len();
    let flat: Vec<f64> = rows.into_iter().flatten().collect();
    Array3::from_shape_vec((b, vertices, 3), flat)
        .map(|a| a.into_pyarray(py))
        .map_err(|e| PyValueError::new_err(e.to_string()))
}

/// Positions as a `[V, 3]` array.
pub fn to_points<'py>(py: Python<'py>, p: &[nalgebra::Vector3<f64>]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = p.iter().flat_map(|v| [v.x, v.y, v.z]).collect();
    Array2::from_shape_vec((p.len(), 3), flat)
        .map(|a| a.into_pyarray(py))
        .map_err(|e| PyValueError::new_err(e.to_string()))
}

/// Index triples (faces or the first three of tets) as an int64 `[N, K]` array.
pub fn to_indices<'py, const K: usize>(py: Python<'py>, t: &[[usize; K]]) -> PyResult<Bound<'py, PyArray2<i64>>> {
    let flat: Vec<i64> = t.iter().flat_map(|f| f.map(|i| i as i64)).collect();
    Array2::from_shape_vec((t.len(), K), flat)
        .map(|a| a.into_pyarray(py))
        .map_err(|e| PyValueError::new_err(e.to_string()))
}
