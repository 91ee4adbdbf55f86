use std::path::Path;

use nalgebra::Vector3;

use super::write_atomically;
use crate::error::{Error, Result};

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
