//! What `cargo xtask warp` writes of an NNWarp run ([`crate::nnwarp`]'s loop):
//! each written frame as VTK with NNWarp's and the linear solve's displacements (and the
//! per-node error against a reference), and the run's `summary.json`. The loop and the
//! network are elsewhere; this is the run's files.

use std::path::Path;

use nalgebra::Vector3;
use serde::Serialize;
use weft_mesh::TetMesh;

use crate::Result;
use crate::nnwarp::{FrameView, ReferenceReport};

/// Writes one frame's VTK, `frame-NNNN.vtk` in `out`: the warped body with NNWarp's and
/// the linear solve's displacements, and with a reference the per-node distance to it.
pub fn write_frame_vtk(out: &Path, f: &FrameView<'_>, rest: &[f64], mesh: &TetMesh) -> Result<()> {
    let (u, u_lin) = (&f.runtime.warped, &f.runtime.linear);
    let node = |v: &[f64], i: usize| Vector3::new(v[3 * i], v[3 * i + 1], v[3 * i + 2]);
    let nodes = rest.len() / 3;
    let error: Option<Vec<f64>> = f
        .reference
        .map(|u_ref| (0..nodes).map(|i| (node(u, i) - node(u_ref, i)).norm()).collect());
    let positions: Vec<Vector3<f64>> = (0..nodes).map(|i| node(rest, i) + node(u, i)).collect();
    let mut fields: Vec<weft_mesh::io::PointField<'_>> =
        vec![("displacement", 3, &u[..]), ("linear_displacement", 3, &u_lin[..])];
    if let Some(e) = &error {
        fields.push(("error", 1, &e[..]));
    }
    weft_mesh::io::write_vtk_tets(
        &out.join(format!("frame-{:04}.vtk", f.frame)),
        &positions,
        mesh.tets(),
        &fields,
    )?;
    Ok(())
}

/// One frame's relative errors in `summary.json` (with a reference only).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameRecord {
    // Fields in the order of their names, as the file has always had them.
    pub frame: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rel_error_linear_solve: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rel_error_nnwarp: Option<f64>,
}

/// `summary.json` of an NNWarp run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WarpRunSummary {
    // Fields in the order of their names, as the file has always had them.
    pub factorization_seconds: f64,
    pub frames: Vec<FrameRecord>,
    /// The material the network was trained on.
    pub material: String,
    pub model: String,
    pub nnwarp_seconds_per_frame: f64,
    pub nodes: usize,
    /// The scene's own material, which the reference runs.
    pub reference_material: String,
    pub reference_seconds_per_frame: Option<f64>,
    pub scene: String,
    pub solve_seconds_per_frame: f64,
    pub tets: usize,
}

/// The body and network a run warped, for its summary.
#[derive(Debug, Clone, Copy)]
pub struct WarpRunSetup<'a> {
    pub scene: &'a str,
    pub model: &'a Path,
    pub material: &'a str,
    pub reference_material: &'a str,
    pub mesh: &'a TetMesh,
    pub factorization_seconds: f64,
}

impl WarpRunSummary {
    /// The summary of `report`, a run of `frames` frames (per-frame times are over at least one).
    pub fn new(setup: &WarpRunSetup<'_>, report: &ReferenceReport, frames: usize) -> Self {
        let frames_run = frames.max(1) as f64;
        let both = |f: &crate::nnwarp::FrameErrors| f.nnwarp.is_some() && f.linear_solve.is_some();
        Self {
            factorization_seconds: setup.factorization_seconds,
            frames: report
                .frames
                .iter()
                .map(|f| FrameRecord {
                    frame: f.frame,
                    rel_error_linear_solve: f.linear_solve.filter(|_| both(f)),
                    rel_error_nnwarp: f.nnwarp.filter(|_| both(f)),
                })
                .collect(),
            material: setup.material.to_string(),
            model: setup.model.display().to_string(),
            nnwarp_seconds_per_frame: report.warp_seconds() / frames_run,
            nodes: setup.mesh.num_vertices(),
            reference_material: setup.reference_material.to_string(),
            reference_seconds_per_frame: report.reference_seconds().map(|s| s / frames_run),
            scene: setup.scene.to_string(),
            solve_seconds_per_frame: report.solve_seconds() / frames_run,
            tets: setup.mesh.num_tets(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nnwarp::FrameErrors;

    fn frame(frame: usize, reference: bool) -> FrameErrors {
        FrameErrors {
            frame,
            solve_seconds: 0.5,
            warp_seconds: 0.25,
            reference_seconds: reference.then_some(2.0),
            nnwarp: reference.then_some(0.01),
            linear_solve: reference.then_some(0.1),
            others: Vec::new(),
        }
    }

    #[test]
    fn the_summary_holds_per_frame_times_and_errors_only_with_a_reference() {
        let mesh = weft_mesh::generators::beam(&weft_mesh::generators::BeamParams {
            cells: [2, 1, 1],
            size: [2.0, 1.0, 1.0],
        })
        .unwrap();
        let setup = WarpRunSetup {
            scene: "beam",
            model: Path::new("m"),
            material: "stvk",
            reference_material: "neo-hookean",
            mesh: &mesh,
            factorization_seconds: 1.0,
        };
        let with = ReferenceReport {
            frames: vec![frame(1, true), frame(2, true)],
        };
        let s = WarpRunSummary::new(&setup, &with, 2);
        assert_eq!((s.solve_seconds_per_frame, s.nnwarp_seconds_per_frame), (0.5, 0.25));
        assert_eq!(s.reference_seconds_per_frame, Some(2.0));
        assert_eq!(s.frames[1].rel_error_nnwarp, Some(0.01));
        let json = serde_json::to_value(&s).unwrap();
        assert_eq!(json["frames"][0]["rel_error_linear_solve"], 0.1);
        let without = ReferenceReport {
            frames: vec![frame(1, false)],
        };
        let s = WarpRunSummary::new(&setup, &without, 0);
        assert_eq!(s.reference_seconds_per_frame, None);
        let json = serde_json::to_value(&s).unwrap();
        assert_eq!(json["frames"][0], serde_json::json!({ "frame": 1 }));
    }
}
