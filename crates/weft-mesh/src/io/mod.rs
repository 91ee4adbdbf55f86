//! Mesh file I/O: Wavefront OBJ (read/write), ASCII PLY (read/write, optional per-vertex
//! colours), TetGen `.node`/`.ele` (read/write) and legacy ASCII VTK (read/write,
//! tetrahedra or triangles). Every format weft writes a mesh in, it reads back.
//!
//! The OBJ reader is hand-written rather than taken from a crate because its errors must
//! name the file and line of the problem (a truncated line, an index out of range), which
//! the common OBJ crates do not report.

mod obj;
mod ply;
mod tetgen;
mod vtk;

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

pub use obj::{parse_obj, read_obj, write_obj};
pub use ply::{parse_ply, read_ply, write_ply};
pub use tetgen::{parse_tetgen, read_tetgen, write_tetgen};
pub use vtk::{PointField, parse_vtk, parse_vtk_tets, read_vtk, read_vtk_tets, write_vtk_tets, write_vtk_triangles};

use crate::error::{Error, Result};
use crate::tetmesh::TetMesh;
use crate::trimesh::TriMesh;

/// A mesh read from a file of either kind.
#[derive(Debug, Clone)]
pub enum AnyMesh {
    Surface(TriMesh),
    Volume(TetMesh),
}

const READABLE: &str = ".obj, .ply, .node, .ele, .vtk (tetrahedra or triangles)";
const WRITABLE: &str = ".obj, .ply, .vtk, .node";

fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

/// Reads a mesh, choosing the format by extension (`.obj` and `.ply` surfaces, `.node`/`.ele`
/// TetGen volumes, `.vtk` legacy unstructured grids of tetrahedra or triangles).
pub fn read_mesh(path: &Path) -> Result<AnyMesh> {
    match extension(path).as_str() {
        "obj" => read_obj(path).map(AnyMesh::Surface),
        "ply" => read_ply(path).map(AnyMesh::Surface),
        "node" | "ele" => read_tetgen(path).map(AnyMesh::Volume),
        "vtk" => read_vtk(path),
        e => Err(Error::UnsupportedFormat {
            path: path.into(),
            extension: e.into(),
            supported: READABLE,
        }),
    }
}

/// Writes a surface mesh by extension (`.obj`, `.ply`, `.vtk`).
pub fn write_surface(path: &Path, mesh: &TriMesh) -> Result<()> {
    match extension(path).as_str() {
        "obj" => write_obj(path, mesh.positions(), mesh.faces()),
        "ply" => write_ply(path, mesh.positions(), mesh.faces(), None),
        "vtk" => write_vtk_triangles(path, mesh.positions(), mesh.faces(), &[]),
        e => Err(Error::UnsupportedFormat {
            path: path.into(),
            extension: e.into(),
            supported: ".obj, .ply, .vtk (a surface has no .node/.ele form)",
        }),
    }
}

/// Writes a volume mesh by extension: `.vtk` and `.node` (+ `.ele`) keep the tetrahedra;
/// `.obj` and `.ply` write the boundary surface.
pub fn write_volume(path: &Path, mesh: &TetMesh) -> Result<()> {
    match extension(path).as_str() {
        "vtk" => write_vtk_tets(path, mesh.positions(), mesh.tets(), &[]),
        "node" | "ele" => write_tetgen(path, mesh),
        "obj" | "ply" => write_surface(path, &mesh.boundary_surface()?.mesh),
        e => Err(Error::UnsupportedFormat {
            path: path.into(),
            extension: e.into(),
            supported: WRITABLE,
        }),
    }
}

pub(crate) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.to_path_buf(),
        source,
    }
}

pub(crate) fn parse_err(path: &Path, line: usize, message: impl Into<String>) -> Error {
    Error::Parse {
        path: PathBuf::from(path),
        line,
        message: message.into(),
    }
}

/// Writes through a buffer, then renames into place, so a failed write never leaves a
/// half-written file under the final name.
pub(crate) fn write_atomically(path: &Path, body: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<()> {
    let tmp = path.with_extension(format!("{}.tmp", extension(path)));
    let file = File::create(&tmp).map_err(io_err(&tmp))?;
    let mut w = BufWriter::new(file);
    body(&mut w).and_then(|_| w.flush()).map_err(io_err(path))?;
    drop(w);
    std::fs::rename(&tmp, path).map_err(io_err(path))
}
