use std::path::Path;

use nalgebra::Vector3;

use super::write_atomically;
use crate::error::{Error, Result};

/// A named per-vertex field for VTK output: 1 component (scalars) or 3 (vectors).
pub type PointField<'a> = (&'a str, usize, &'a [f64]);

fn write_vtk<const N: usize>(
    path: &Path,
    positions: &[Vector3<f64>],
    cells: &[[usize; N]],
    cell_type: u8,
    fields: &[PointField<'_>],
) -> Result<()> {
    for &(_, comps, data) in fields {
        if !(comps == 1 || comps == 3) || data.len() != comps * positions.len() {
            return Err(Error::LengthMismatch {
                what: "VTK point field values (1 or 3 components per vertex)",
                expected: 3 * positions.len(),
                got: data.len(),
            });
        }
    }
    write_atomically(path, |w| {
        writeln!(w, "# vtk DataFile Version 3.0\nweft\nASCII\nDATASET UNSTRUCTURED_GRID")?;
        writeln!(w, "POINTS {} double", positions.len())?;
        for p in positions {
            writeln!(w, "{:?} {:?} {:?}", p.x, p.y, p.z)?;
        }
        writeln!(w, "CELLS {} {}", cells.len(), cells.len() * (N + 1))?;
        for c in cells {
            write!(w, "{N}")?;
            for v in c {
                write!(w, " {v}")?;
            }
            writeln!(w)?;
        }
        writeln!(w, "CELL_TYPES {}", cells.len())?;
        for _ in cells {
            writeln!(w, "{cell_type}")?;
        }
        if !fields.is_empty() {
            writeln!(w, "POINT_DATA {}", positions.len())?;
        }
        for &(name, comps, data) in fields {
            if comps == 1 {
                writeln!(w, "SCALARS {name} double 1\nLOOKUP_TABLE default")?;
            } else {
                writeln!(w, "VECTORS {name} double")?;
            }
            for chunk in data.chunks(comps) {
                let s: Vec<String> = chunk.iter().map(|x| format!("{x:?}")).collect();
                writeln!(w, "{}", s.join(" "))?;
            }
        }
        Ok(())
    })
}

/// Legacy VTK unstructured grid of tetrahedra (cell type 10) with optional point fields.
pub fn write_vtk_tets(
    path: &Path,
    positions: &[Vector3<f64>],
    tets: &[[usize; 4]],
    fields: &[PointField<'_>],
) -> Result<()> {
    write_vtk(path, positions, tets, 10, fields)
}

/// Legacy VTK unstructured grid of triangles (cell type 5) with optional point fields.
pub fn write_vtk_triangles(
    path: &Path,
    positions: &[Vector3<f64>],
    faces: &[[usize; 3]],
    fields: &[PointField<'_>],
) -> Result<()> {
    write_vtk(path, positions, faces, 5, fields)
}
