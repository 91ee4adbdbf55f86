use std::path::Path;

use nalgebra::Vector3;

use super::{AnyMesh, io_err, parse_err, write_atomically};
use crate::error::{Error, Result};
use crate::tetmesh::TetMesh;
use crate::trimesh::TriMesh;

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

/// Reads the tetrahedra (cell type 10) of a legacy ASCII VTK unstructured grid, as written
/// by [`write_vtk_tets`], ParaView or gmsh. Other cell types are skipped; a file without
/// tetrahedra is an error.
pub fn read_vtk_tets(path: &Path) -> Result<TetMesh> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    parse_vtk_tets(&text, path)
}

/// Parses the text of a legacy VTK unstructured grid (see [`read_vtk_tets`]); `path` names
/// the file in errors.
pub fn parse_vtk_tets(text: &str, path: &Path) -> Result<TetMesh> {
    let (positions, cells) = parse_grid(text, path)?;
    let tets = cells_of::<4>(&cells, TETRAHEDRON, "tetrahedron", path)?;
    if tets.is_empty() {
        return Err(parse_err(path, 1, "no tetrahedra (VTK cell type 10) in the file"));
    }
    TetMesh::new(positions, tets)
}

/// Reads a legacy ASCII VTK unstructured grid of either kind: its tetrahedra (cell type
/// 10) as a volume, or, in a file without tetrahedra, its triangles (cell type 5) as a
/// surface ([`write_vtk_triangles`] writes such a file). Other cell types are skipped.
pub fn read_vtk(path: &Path) -> Result<AnyMesh> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    parse_vtk(&text, path)
}

/// Parses the text of a legacy VTK unstructured grid (see [`read_vtk`]).
pub fn parse_vtk(text: &str, path: &Path) -> Result<AnyMesh> {
    let (positions, cells) = parse_grid(text, path)?;
    let tets = cells_of::<4>(&cells, TETRAHEDRON, "tetrahedron", path)?;
    if !tets.is_empty() {
        return Ok(AnyMesh::Volume(TetMesh::new(positions, tets)?));
    }
    let triangles = cells_of::<3>(&cells, TRIANGLE, "triangle", path)?;
    if triangles.is_empty() {
        return Err(parse_err(
            path,
            1,
            "no tetrahedra (VTK cell type 10) or triangles (cell type 5) in the file",
        ));
    }
    Ok(AnyMesh::Surface(TriMesh::new(positions, triangles)?))
}

const TRIANGLE: usize = 5;
const TETRAHEDRON: usize = 10;

/// A cell of a grid: the line it is on, its VTK type and its vertex indices.
type Cell = (usize, usize, Vec<usize>);

/// The cells of type `kind`, each of `N` indices (another count is an error on its line).
fn cells_of<const N: usize>(cells: &[Cell], kind: usize, what: &str, path: &Path) -> Result<Vec<[usize; N]>> {
    cells
        .iter()
        .filter(|(_, t, _)| *t == kind)
        .map(|(line, _, ids)| {
            <[usize; N]>::try_from(ids.as_slice())
                .map_err(|_| parse_err(path, *line, format!("{what} with {} indices", ids.len())))
        })
        .collect()
}

/// The points and cells of a legacy VTK unstructured grid. Header counts are checked
/// against the tokens that follow before anything is allocated for them.
fn parse_grid(text: &str, path: &Path) -> Result<(Vec<Vector3<f64>>, Vec<Cell>)> {
    // Tokens with their line numbers: legacy VTK lets numbers wrap across lines.
    let tokens: Vec<(usize, &str)> = text
        .lines()
        .enumerate()
        .flat_map(|(i, l)| l.split_whitespace().map(move |t| (i + 1, t)))
        .collect();
    let last_line = text.lines().count();
    let find = |key: &str| tokens.iter().position(|(_, t)| t.eq_ignore_ascii_case(key));
    let number = |k: usize, what: &str| -> Result<f64> {
        let (line, tok) = tokens
            .get(k)
            .ok_or_else(|| parse_err(path, last_line, format!("file ends inside {what}")))?;
        tok.parse()
            .map_err(|_| parse_err(path, *line, format!("bad {what} {tok:?}")))
    };
    let count = |k: usize, what: &str| -> Result<usize> {
        let v = number(k, what)?;
        if v >= 0.0 && v.fract() == 0.0 {
            Ok(v as usize)
        } else {
            Err(parse_err(path, tokens[k].0, format!("bad {what} {v}")))
        }
    };
    if !text.contains("UNSTRUCTURED_GRID") {
        return Err(parse_err(path, 1, "not a legacy VTK UNSTRUCTURED_GRID file"));
    }
    let p = find("POINTS").ok_or_else(|| parse_err(path, 1, "no POINTS section"))?;
    let np = count(p + 1, "point count")?;
    let mut positions = Vec::with_capacity(np.min(tokens.len() / 3));
    for i in 0..np {
        let base = p + 3 + 3 * i;
        positions.push(nalgebra::Vector3::new(
            number(base, "coordinate")?,
            number(base + 1, "coordinate")?,
            number(base + 2, "coordinate")?,
        ));
    }
    let c = find("CELLS").ok_or_else(|| parse_err(path, 1, "no CELLS section"))?;
    let nc = count(c + 1, "cell count")?;
    let mut cells = Vec::with_capacity(nc.min(tokens.len()));
    let mut k = c + 3;
    for _ in 0..nc {
        let n = count(k, "cell size")?;
        let ids = (1..=n)
            .map(|j| count(k + j, "cell index"))
            .collect::<Result<Vec<_>>>()?;
        cells.push((tokens[k].0, ids));
        k = n
            .checked_add(1)
            .and_then(|m| k.checked_add(m))
            .ok_or_else(|| parse_err(path, tokens[k].0, format!("bad cell size {n}")))?;
    }
    let t = find("CELL_TYPES").ok_or_else(|| parse_err(path, 1, "no CELL_TYPES section"))?;
    let cells = cells
        .into_iter()
        .enumerate()
        .map(|(i, (line, ids))| Ok((line, count(t + 2 + i, "cell type")?, ids)))
        .collect::<Result<Vec<Cell>>>()?;
    Ok((positions, cells))
}
