use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use super::{io_err, parse_err, write_atomically};
use crate::error::Result;
use crate::tetmesh::TetMesh;

fn pair(path: &Path) -> (PathBuf, PathBuf) {
    (path.with_extension("node"), path.with_extension("ele"))
}

/// Non-empty, comment-stripped lines with their 1-based line numbers.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(i, l)| {
        let toks: Vec<&str> = l.split('#').next().unwrap_or("").split_whitespace().collect();
        (!toks.is_empty()).then_some((i + 1, toks))
    })
}

fn num<T: std::str::FromStr>(path: &Path, line: usize, tok: Option<&&str>, what: &str) -> Result<T> {
    let tok = tok.ok_or_else(|| parse_err(path, line, format!("missing {what}")))?;
    tok.parse()
        .map_err(|_| parse_err(path, line, format!("bad {what} {tok:?}")))
}

/// Reads a TetGen `.node` + `.ele` pair (either path, or the shared stem with either
/// extension). Indices may start at 0 or 1, as TetGen allows; the `.node` file's first
/// index decides.
pub fn read_tetgen(path: &Path) -> Result<TetMesh> {
    let (node, ele) = pair(path);
    let ntext = std::fs::read_to_string(&node).map_err(io_err(&node))?;
    let etext = std::fs::read_to_string(&ele).map_err(io_err(&ele))?;
    parse_tetgen(&ntext, &etext, &node, &ele)
}

/// Parses the text of a TetGen `.node` and `.ele` pair; `node` and `ele` name the files in
/// errors. Counts in the headers are checked against the lines that follow before
/// anything is allocated for them, so a lying header costs nothing.
pub fn parse_tetgen(ntext: &str, etext: &str, node: &Path, ele: &Path) -> Result<TetMesh> {
    let (node, ele) = (node.to_path_buf(), ele.to_path_buf());
    let mut lines = data_lines(ntext);
    let (hl, header) = lines.next().ok_or_else(|| parse_err(&node, 1, "empty .node file"))?;
    let count: usize = num(&node, hl, header.first(), "point count")?;
    let dim: usize = num(&node, hl, header.get(1), "dimension")?;
    if dim != 3 {
        return Err(parse_err(&node, hl, format!("dimension is {dim}, expected 3")));
    }
    let mut positions = Vec::with_capacity(count.min(ntext.lines().count()));
    let mut base = None;
    for _ in 0..count {
        let (l, t) = lines.next().ok_or_else(|| {
            parse_err(
                &node,
                ntext.lines().count(),
                format!("file ends after {} of {count} points", positions.len()),
            )
        })?;
        let id: usize = num(&node, l, t.first(), "point index")?;
        let b = *base.get_or_insert(id.min(1));
        if id != positions.len() + b {
            return Err(parse_err(
                &node,
                l,
                format!("point index {id}, expected {}", positions.len() + b),
            ));
        }
        let c = [
            num(&node, l, t.get(1), "x")?,
            num(&node, l, t.get(2), "y")?,
            num(&node, l, t.get(3), "z")?,
        ];
        positions.push(Vector3::from(c));
    }
    let base = base.unwrap_or(0);

    let mut lines = data_lines(etext);
    let (hl, header) = lines.next().ok_or_else(|| parse_err(&ele, 1, "empty .ele file"))?;
    let count: usize = num(&ele, hl, header.first(), "tetrahedron count")?;
    let per: usize = num(&ele, hl, header.get(1), "nodes per tetrahedron")?;
    if per != 4 {
        return Err(parse_err(
            &ele,
            hl,
            format!("{per} nodes per tetrahedron; only linear (4-node) tets are supported"),
        ));
    }
    let mut tets = Vec::with_capacity(count.min(etext.lines().count()));
    for _ in 0..count {
        let (l, t) = lines.next().ok_or_else(|| {
            parse_err(
                &ele,
                etext.lines().count(),
                format!("file ends after {} of {count} tetrahedra", tets.len()),
            )
        })?;
        let mut tet = [0usize; 4];
        for k in 0..4 {
            let v: usize = num(&ele, l, t.get(k + 1), "node index")?;
            if v < base || v - base >= positions.len() {
                return Err(parse_err(
                    &ele,
                    l,
                    format!(
                        "node index {v} is out of range ({} points, base {base})",
                        positions.len()
                    ),
                ));
            }
            tet[k] = v - base;
        }
        tets.push(tet);
    }
    TetMesh::new(positions, tets)
}

/// Writes `stem.node` and `stem.ele` (0-based) for the given path's stem.
pub fn write_tetgen(path: &Path, mesh: &TetMesh) -> Result<()> {
    let (node, ele) = pair(path);
    write_atomically(&node, |w| {
        writeln!(w, "{} 3 0 0", mesh.num_vertices())?;
        for (i, p) in mesh.positions().iter().enumerate() {
            writeln!(w, "{i} {:?} {:?} {:?}", p.x, p.y, p.z)?;
        }
        Ok(())
    })?;
    write_atomically(&ele, |w| {
        writeln!(w, "{} 4 0", mesh.num_tets())?;
        for (i, t) in mesh.tets().iter().enumerate() {
            writeln!(w, "{i} {} {} {} {}", t[0], t[1], t[2], t[3])?;
        }
        Ok(())
    })
}
