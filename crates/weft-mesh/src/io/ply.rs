use std::path::Path;

use nalgebra::Vector3;

use super::{io_err, parse_err, write_atomically};
use crate::error::{Error, Result};
use crate::trimesh::TriMesh;

/// Writes an ASCII PLY, with optional per-vertex RGB colours (e.g. an error map).
pub fn write_ply(
    path: &Path,
    positions: &[Vector3<f64>],
    faces: &[[usize; 3]],
    colors: Option<&[[u8; 3]]>,
) -> Result<()> {
    if let Some(c) = colors.filter(|c| c.len() != positions.len()) {
        return Err(Error::LengthMismatch {
            what: "PLY vertex colours",
            expected: positions.len(),
            got: c.len(),
        });
    }
    write_atomically(path, |w| {
        writeln!(w, "ply\nformat ascii 1.0\ncomment written by weft")?;
        writeln!(
            w,
            "element vertex {}\nproperty double x\nproperty double y\nproperty double z",
            positions.len()
        )?;
        if colors.is_some() {
            writeln!(w, "property uchar red\nproperty uchar green\nproperty uchar blue")?;
        }
        writeln!(
            w,
            "element face {}\nproperty list uchar int vertex_indices\nend_header",
            faces.len()
        )?;
        for (i, p) in positions.iter().enumerate() {
            match colors {
                Some(c) => writeln!(w, "{:?} {:?} {:?} {} {} {}", p.x, p.y, p.z, c[i][0], c[i][1], c[i][2])?,
                None => writeln!(w, "{:?} {:?} {:?}", p.x, p.y, p.z)?,
            }
        }
        for f in faces {
            writeln!(w, "3 {} {} {}", f[0], f[1], f[2])?;
        }
        Ok(())
    })
}

/// Reads an ASCII PLY surface, as written by [`write_ply`], MeshLab or Blender: the
/// `x y z` properties of `vertex` (others, such as colours, are skipped) and the index
/// list of `face` (polygons fan-triangulated, as [`super::read_obj`] does); other elements
/// are skipped. A binary PLY is a typed error naming the format.
pub fn read_ply(path: &Path) -> Result<TriMesh> {
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    // A binary body is not UTF-8; its header is, and says which format it is.
    let text = String::from_utf8_lossy(&bytes);
    parse_ply(&text, path)
}

/// One `element` of a PLY header: its name, count and properties (a list property is
/// `(name, true)`).
struct Element<'a> {
    name: &'a str,
    count: usize,
    properties: Vec<(&'a str, bool)>,
    line: usize,
}

/// Parses the text of an ASCII PLY (see [`read_ply`]); `path` names the file in errors.
/// Header counts are checked against the lines that follow before anything is
/// allocated for them.
pub fn parse_ply(text: &str, path: &Path) -> Result<TriMesh> {
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l));
    if lines.next().map(|(_, l)| l.trim()) != Some("ply") {
        return Err(parse_err(path, 1, "not a PLY file (the first line is not `ply`)"));
    }
    let mut elements: Vec<Element<'_>> = Vec::new();
    let mut header_end = None;
    for (line, l) in lines.by_ref() {
        let mut it = l.split_whitespace();
        match it.next() {
            Some("format") => match it.next() {
                Some("ascii") => {}
                other => {
                    return Err(parse_err(
                        path,
                        line,
                        format!(
                            "PLY format {:?} is not supported; only `format ascii 1.0` is (convert with MeshLab or write .obj)",
                            other.unwrap_or("")
                        ),
                    ));
                }
            },
            Some("element") => {
                let (Some(name), Some(count)) = (it.next(), it.next()) else {
                    return Err(parse_err(path, line, "an element needs a name and a count"));
                };
                let count = count
                    .parse()
                    .map_err(|_| parse_err(path, line, format!("bad element count {count:?}")))?;
                elements.push(Element {
                    name,
                    count,
                    properties: Vec::new(),
                    line,
                });
            }
            Some("property") => {
                let element = elements
                    .last_mut()
                    .ok_or_else(|| parse_err(path, line, "a property before any element"))?;
                let words: Vec<&str> = it.collect();
                let list = words.first() == Some(&"list");
                let name = words
                    .last()
                    .copied()
                    .ok_or_else(|| parse_err(path, line, "a property without a name"))?;
                element.properties.push((name, list));
            }
            Some("end_header") => {
                header_end = Some(line);
                break;
            }
            _ => {}
        }
    }
    let header_end = header_end.ok_or_else(|| parse_err(path, 1, "no `end_header` line"))?;
    let mut body = lines.filter(|(_, l)| !l.trim().is_empty());
    let remaining = text.lines().count().saturating_sub(header_end);
    let mut positions = Vec::new();
    let mut faces = Vec::new();
    for element in &elements {
        if element.count > remaining {
            return Err(parse_err(
                path,
                element.line,
                format!(
                    "element {} declares {} rows but the file has {remaining} lines after its header",
                    element.name, element.count
                ),
            ));
        }
        let coordinate = |axis: &str| element.properties.iter().position(|&(n, list)| n == axis && !list);
        let is_vertex = element.name == "vertex";
        let xyz = [coordinate("x"), coordinate("y"), coordinate("z")];
        if is_vertex && xyz.iter().any(Option::is_none) {
            return Err(parse_err(
                path,
                element.line,
                "the vertex element has no x, y and z properties",
            ));
        }
        if is_vertex && element.properties.iter().any(|&(_, list)| list) {
            return Err(parse_err(
                path,
                element.line,
                "a list property on vertices is not supported",
            ));
        }
        let indices = element
            .properties
            .iter()
            .position(|&(n, list)| list && (n == "vertex_indices" || n == "vertex_index"));
        let indices = match (element.name == "face", indices) {
            (true, None) => {
                return Err(parse_err(
                    path,
                    element.line,
                    "the face element has no `list … vertex_indices` property",
                ));
            }
            (_, i) => i.unwrap_or(0),
        };
        for _ in 0..element.count {
            let (line, l) = body.next().ok_or_else(|| {
                parse_err(
                    path,
                    text.lines().count(),
                    format!("file ends inside element {}", element.name),
                )
            })?;
            let tokens: Vec<&str> = l.split_whitespace().collect();
            if is_vertex {
                if tokens.len() != element.properties.len() {
                    return Err(parse_err(
                        path,
                        line,
                        format!(
                            "vertex has {} values, expected {}",
                            tokens.len(),
                            element.properties.len()
                        ),
                    ));
                }
                let mut c = [0.0; 3];
                for (slot, k) in c.iter_mut().zip(xyz.into_iter().flatten()) {
                    *slot = tokens[k]
                        .parse()
                        .map_err(|_| parse_err(path, line, format!("bad coordinate {:?}", tokens[k])))?;
                }
                positions.push(Vector3::from(c));
            } else if element.name == "face" {
                let listed = property_values(&tokens, &element.properties, indices, path, line)?;
                if listed.len() < 3 {
                    return Err(parse_err(
                        path,
                        line,
                        format!("face has {} vertices; a face needs at least 3", listed.len()),
                    ));
                }
                let poly = listed
                    .iter()
                    .map(|t| {
                        t.parse::<usize>().ok().filter(|&v| v < positions.len()).ok_or_else(|| {
                            parse_err(
                                path,
                                line,
                                format!("face index {t:?} is not one of the {} vertices read", positions.len()),
                            )
                        })
                    })
                    .collect::<Result<Vec<usize>>>()?;
                for k in 1..poly.len() - 1 {
                    faces.push([poly[0], poly[k], poly[k + 1]]);
                }
            }
        }
    }
    if !elements.iter().any(|e| e.name == "vertex") {
        return Err(parse_err(path, header_end, "no vertex element"));
    }
    TriMesh::new(positions, faces)
}

/// The values of property `wanted` in one row of an element with `properties` (in header
/// order; a list is its length, then that many values). A row with fewer or more values
/// than its properties declare is an error on its line.
fn property_values<'t>(
    tokens: &[&'t str],
    properties: &[(&str, bool)],
    wanted: usize,
    path: &Path,
    line: usize,
) -> Result<Vec<&'t str>> {
    let mut k = 0;
    let mut found = Vec::new();
    for (p, &(name, list)) in properties.iter().enumerate() {
        let len = if list {
            let len = tokens
                .get(k)
                .and_then(|t| t.parse::<usize>().ok())
                .ok_or_else(|| parse_err(path, line, format!("the list {name} must start with its length")))?;
            k += 1;
            len
        } else {
            1
        };
        let end = k.checked_add(len).filter(|&end| end <= tokens.len()).ok_or_else(|| {
            parse_err(
                path,
                line,
                format!(
                    "the row holds {} values, fewer than its properties declare",
                    tokens.len()
                ),
            )
        })?;
        if p == wanted {
            found = tokens[k..end].to_vec();
        }
        k = end;
    }
    if k != tokens.len() {
        return Err(parse_err(
            path,
            line,
            format!(
                "the row holds {} values, more than its properties declare ({k})",
                tokens.len()
            ),
        ));
    }
    Ok(found)
}
