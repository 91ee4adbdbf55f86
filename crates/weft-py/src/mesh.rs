//! Meshes on numpy: the built-in generators and mesh files (weft-mesh).

use std::path::PathBuf;

use numpy::{PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays;
use crate::errors;

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(mesh_sheet, m)?)?;
    m.add_function(wrap_pyfunction!(mesh_ball, m)?)?;
    m.add_function(wrap_pyfunction!(mesh_read, m)?)?;
    m.add_function(wrap_pyfunction!(mesh_write, m)?)?;
    Ok(())
}

type Surface<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<i64>>);

fn surface<'py>(py: Python<'py>, m: &weft_mesh::TriMesh) -> PyResult<Surface<'py>> {
    Ok((
        arrays::to_points(py, m.positions())?,
        arrays::to_indices(py, m.faces())?,
    ))
}

/// A square sheet of `n × n` vertices and side `size` (m) in the xy plane.
#[pyfunction]
#[pyo3(signature = (n, size = 1.0))]
fn mesh_sheet(py: Python<'_>, n: usize, size: f64) -> PyResult<Surface<'_>> {
    surface(py, &weft_mesh::generators::sheet(n, size).map_err(errors::mesh)?)
}

/// A UV sphere of `segments` around, `rings` from pole to pole and `radius` (m).
#[pyfunction]
#[pyo3(signature = (segments, rings, radius = 0.5))]
fn mesh_ball(py: Python<'_>, segments: usize, rings: usize, radius: f64) -> PyResult<Surface<'_>> {
    surface(
        py,
        &weft_mesh::generators::ball(segments, rings, radius).map_err(errors::mesh)?,
    )
}

/// A mesh file (.obj, .ply or .vtk triangles; .node/.ele or .vtk tetrahedra) as a dict: `vertices` and `faces`,
/// or `vertices` and `tets`.
#[pyfunction]
fn mesh_read(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    match weft_mesh::io::read_mesh(&path).map_err(errors::mesh)? {
        weft_mesh::io::AnyMesh::Surface(m) => {
            d.set_item("vertices", arrays::to_points(py, m.positions())?)?;
            d.set_item("faces", arrays::to_indices(py, m.faces())?)?;
        }
        weft_mesh::io::AnyMesh::Volume(m) => {
            d.set_item("vertices", arrays::to_points(py, m.positions())?)?;
            d.set_item("tets", arrays::to_indices(py, m.tets())?)?;
        }
    }
    Ok(d)
}

/// Writes a surface by extension (.obj, .ply, .vtk); the mesh is validated first.
#[pyfunction]
fn mesh_write(path: PathBuf, vertices: PyReadonlyArray2<'_, f64>, faces: PyReadonlyArray2<'_, i64>) -> PyResult<()> {
    let mesh = arrays::trimesh(&vertices, &faces)?;
    weft_mesh::io::write_surface(&path, &mesh).map_err(errors::mesh)
}
