use std::path::Path;

use nalgebra::Vector3;

use super::{io_err, parse_err, write_atomically};
use crate::error::Result;
use crate::trimesh::TriMesh;

/// Reads an OBJ file as a [`TriMesh`]; polygons are fan-triangulated, `v/vt/vn` face
/// forms and negative (relative) indices are accepted, other statements ignored.
pub fn read_obj(path: &Path) -> Result<TriMesh> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    parse_obj(&text, path)
}

/// Parses OBJ text; `path` only names the source in errors.
pub fn parse_obj(text: &str, path: &Path) -> Result<TriMesh> {
    let mut positions = Vec::new();
    let mut faces = Vec::new();
    for (ln, raw) in text.lines().enumerate() {
        let line = ln + 1;
        let content = raw.split('#').next().unwrap_or("");
        let mut it = content.split_whitespace();
        match it.next() {
            Some("v") => {
                let mut c = [0.0; 3];
                for (k, slot) in c.iter_mut().enumerate() {
                    let tok = it
                        .next()
                        .ok_or_else(|| parse_err(path, line, format!("vertex has {k} coordinates, expected 3")))?;
                    *slot = tok
                        .parse()
                        .map_err(|_| parse_err(path, line, format!("bad coordinate {tok:?}")))?;
                }
                positions.push(Vector3::from(c));
            }
            Some("f") => {
                let mut poly = Vec::new();
                for tok in it {
                    let first = tok.split('/').next().unwrap_or("");
                    let idx: i64 = first
                        .parse()
                        .map_err(|_| parse_err(path, line, format!("bad face index {tok:?}")))?;
                    let n = positions.len() as i64;
                    let v = if idx > 0 {
                        idx - 1
                    } else if idx < 0 {
                        n.saturating_add(idx)
                    } else {
                        -1
                    };
                    if v < 0 || v >= n {
                        return Err(parse_err(
                            path,
                            line,
                            format!("face index {idx} is out of range: {n} vertices defined so far"),
                        ));
                    }
                    poly.push(v as usize);
                }
                if poly.len() < 3 {
                    return Err(parse_err(
                        path,
                        line,
                        format!("face has {} vertices, expected at least 3", poly.len()),
                    ));
                }
                for k in 1..poly.len() - 1 {
                    faces.push([poly[0], poly[k], poly[k + 1]]);
                }
            }
            _ => {}
        }
    }
    TriMesh::new(positions, faces)
}

/// Writes positions and triangles as OBJ (1-based indices, full f64 round-trip precision).
pub fn write_obj(path: &Path, positions: &[Vector3<f64>], faces: &[[usize; 3]]) -> Result<()> {
    write_atomically(path, |w| {
        writeln!(w, "# weft: {} vertices, {} faces", positions.len(), faces.len())?;
        for p in positions {
            writeln!(w, "v {:?} {:?} {:?}", p.x, p.y, p.z)?;
        }
        for f in faces {
            writeln!(w, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1)?;
        }
        Ok(())
    })
}
