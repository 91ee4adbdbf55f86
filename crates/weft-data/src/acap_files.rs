//! The inputs `cargo xtask acap` gathers from files: the rest mesh (a file, or a `simulate`
//! directory's `rest.obj`), the frames to encode (a directory's `frames.safetensors`, then
//! deformed OBJs of the rest's connectivity), and the pins to decode with (given, or those
//! `acap encode` recorded beside the features). The array formats are [`crate::arrays`]';
//! ACAP itself is weft-acap's.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use weft_mesh::TriMesh;

use crate::arrays::{pin_file, read_pin_positions, read_pin_record, read_safetensors_frames, safetensors_metadata};
use crate::error::{Context, Error, Result, ensure};

/// The rest mesh at `path`, or `path/rest.obj` for a directory.
pub fn rest_mesh(path: &Path) -> Result<TriMesh> {
    let file = if path.is_dir() {
        path.join("rest.obj")
    } else {
        path.to_path_buf()
    };
    weft_mesh::io::read_obj(&file).with_context(|| format!("reading rest mesh {}", file.display()))
}

/// The frames to encode against `rest` read from `rest_path`: a directory's
/// `frames.safetensors` first, then each of `meshes` (which must share the rest's faces).
/// Refuses nothing to encode and `pins` out of range or repeated.
pub fn frames_to_encode(
    rest_path: &Path,
    rest: &TriMesh,
    meshes: &[PathBuf],
    pins: &[usize],
) -> Result<Vec<Vec<Vector3<f64>>>> {
    let nv = rest.num_vertices();
    let mut frames = Vec::new();
    if rest_path.is_dir() {
        frames.extend(read_safetensors_frames(&rest_path.join("frames.safetensors"), nv)?);
    }
    for m in meshes {
        let mesh = weft_mesh::io::read_obj(m).with_context(|| format!("reading {}", m.display()))?;
        ensure!(
            mesh.faces() == rest.faces(),
            "{} does not have the rest mesh's connectivity ({} faces vs {})",
            m.display(),
            mesh.num_faces(),
            rest.num_faces()
        );
        frames.push(mesh.positions().to_vec());
    }
    ensure!(
        !frames.is_empty(),
        "nothing to encode: give --mesh files or a simulate directory as --rest"
    );
    for (k, &p) in pins.iter().enumerate() {
        ensure!(p < nv, "pin {p} is out of range for {nv} vertices");
        ensure!(!pins[..k].contains(&p), "vertex {p} is pinned twice in --pin");
    }
    Ok(frames)
}

/// `pins`, or without them the grasp vertices in the metadata of `frames.safetensors`.
pub fn round_trip_pins(frames_file: &Path, pins: &[usize]) -> Result<Vec<usize>> {
    if !pins.is_empty() {
        return Ok(pins.to_vec());
    }
    let text = safetensors_metadata(frames_file, "grasp_vertices")?
        .context("no --pin given and no grasp_vertices in the frames' metadata")?;
    serde_json::from_str(&text).with_context(|| format!("grasp_vertices metadata {text:?}"))
}

/// The pins to decode `frames` frames of `features` with, and their positions per frame:
/// `pins` (or those recorded at encode time) at `pin_positions` (`x,y,z;x,y,z;...`, the
/// same in every frame) or at the positions recorded at encode time.
pub fn decode_pins(
    features: &Path,
    frames: usize,
    pins: &[usize],
    pin_positions: Option<&str>,
) -> Result<(Vec<usize>, Vec<Vec<Vector3<f64>>>)> {
    let recorded = read_pin_record(features)?;
    let pins: Vec<usize> = match &recorded {
        _ if !pins.is_empty() => pins.to_vec(),
        Some(r) => r.pins.clone(),
        None => {
            return Err(Error::Invalid(format!(
                "no --pin given and no {} from `acap encode`",
                pin_file(features, "json").display()
            )));
        }
    };
    let positions = match pin_positions {
        Some(text) => {
            let xyz = parse_pin_positions(text)?;
            ensure!(
                xyz.len() == pins.len(),
                "{} pin positions for {} pins",
                xyz.len(),
                pins.len()
            );
            vec![xyz; frames]
        }
        None => {
            let r = recorded.as_ref().with_context(|| {
                format!(
                    "no --pin-positions given and no {}",
                    pin_file(features, "json").display()
                )
            })?;
            ensure!(
                r.pins == pins,
                "--pin {pins:?} differs from the pins {:?} recorded at encode time",
                r.pins
            );
            read_pin_positions(features, frames, pins.len())?
        }
    };
    Ok((pins, positions))
}

/// `x,y,z;x,y,z;...` → points.
pub fn parse_pin_positions(text: &str) -> Result<Vec<Vector3<f64>>> {
    text.split(';')
        .filter(|s| !s.trim().is_empty())
        .map(|triple| {
            let c: Vec<f64> = triple
                .split(',')
                .map(|v| {
                    v.trim()
                        .parse::<f64>()
                        .map_err(|e| Error::Invalid(format!("bad coordinate {v:?} in {triple:?}: {e}")))
                })
                .collect::<Result<_>>()?;
            ensure!(c.len() == 3, "pin position {triple:?} must have 3 coordinates");
            Ok(Vector3::new(c[0], c[1], c[2]))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pin_positions_parse_and_bad_ones_are_named() {
        let p = parse_pin_positions("0,1,2; -1.5,0,3e-2;").unwrap();
        assert_eq!(p, vec![Vector3::new(0.0, 1.0, 2.0), Vector3::new(-1.5, 0.0, 0.03)]);
        assert!(
            parse_pin_positions("0,1")
                .unwrap_err()
                .to_string()
                .contains("3 coordinates")
        );
        assert!(parse_pin_positions("0,x,1").unwrap_err().to_string().contains("\"x\""));
    }

    #[test]
    fn given_pins_win_and_missing_records_are_refused() {
        let f = Path::new("/nonexistent/weft-data-acap-files/F.npy");
        assert_eq!(round_trip_pins(f, &[3, 4]).unwrap(), vec![3, 4]);
        let (pins, at) = decode_pins(f, 2, &[1], Some("0,0,1")).unwrap();
        assert_eq!((pins, at.len()), (vec![1], 2));
        assert!(decode_pins(f, 2, &[], None).is_err());
    }
}
