//! A projection of one predicted cloth mesh file, as `cargo xtask project` runs it: the rest
//! and predicted meshes read and checked to share their connectivity, a layer's forward
//! solve, the projected mesh written, and a report of the solve and of the edge strains
//! before and after. Training and evaluation project tensors, not files; they use the
//! layers directly.

use std::path::Path;

use serde::Serialize;
use weft_mesh::TriMesh;
use weft_mesh::io::{self, AnyMesh};

use crate::{
    Error, InextensibilityLayer, QuasistaticLayer, QuasistaticParams, QuasistaticReport, Result, SocpReport,
    SocpSettings, ZeroLengthScaling, strain_summary,
};

/// Reads the rest and predicted cloth surfaces, refusing volumes and a prediction whose
/// vertices or faces are not the rest mesh's.
pub fn read_rest_and_prediction(rest: &Path, pred: &Path) -> Result<(TriMesh, TriMesh)> {
    let surface = |path: &Path, what: &str| -> Result<TriMesh> {
        match io::read_mesh(path).map_err(|e| Error::MeshFile(format!("reading {what} {}: {e}", path.display())))? {
            AnyMesh::Surface(m) => Ok(m),
            AnyMesh::Volume(_) => Err(Error::MeshFile(format!(
                "{what} {} is a volume mesh; the projection layers take a cloth surface (.obj)",
                path.display()
            ))),
        }
    };
    let rest_mesh = surface(rest, "rest mesh")?;
    let pred_mesh = surface(pred, "prediction")?;
    if rest_mesh.num_vertices() != pred_mesh.num_vertices() {
        return Err(Error::MeshFile(format!(
            "{} has {} vertices but {} has {}",
            pred.display(),
            pred_mesh.num_vertices(),
            rest.display(),
            rest_mesh.num_vertices()
        )));
    }
    if rest_mesh.faces() != pred_mesh.faces() {
        return Err(Error::MeshFile(format!(
            "{} and {} have different faces; the prediction must share the rest mesh's connectivity",
            pred.display(),
            rest.display()
        )));
    }
    Ok((rest_mesh, pred_mesh))
}

/// What one projection of a file did (`solver`: the layer's own report).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProjectionReport<S> {
    pub layer: &'static str,
    pub solve_time_seconds: f64,
    pub iterations: usize,
    pub max_edge_strain_before: f64,
    pub max_edge_strain_after: f64,
    // E = Σ ½ k (l − l̄)² with k = 1 N/m, split by stretched / compressed edges.
    pub stretching_energy_before: f64,
    pub stretching_energy_after: f64,
    pub compression_energy_before: f64,
    pub compression_energy_after: f64,
    pub solver: S,
}

/// A projected configuration (flat positions) and its report.
pub type Projected<S> = (Vec<f64>, ProjectionReport<S>);

fn report<S>(
    layer: &'static str,
    rest: &crate::RestShape,
    (pred, projected): (&[f64], &[f64]),
    (solve_time_seconds, iterations): (f64, usize),
    solver: S,
) -> Result<ProjectionReport<S>> {
    let before = strain_summary(rest, pred, 1.0)?;
    let after = strain_summary(rest, projected, 1.0)?;
    Ok(ProjectionReport {
        layer,
        solve_time_seconds,
        iterations,
        max_edge_strain_before: before.max_strain,
        max_edge_strain_after: after.max_strain,
        stretching_energy_before: before.stretching_energy,
        stretching_energy_after: after.stretching_energy,
        compression_energy_before: before.compression_energy,
        compression_energy_after: after.compression_energy,
        solver,
    })
}

/// The inextensibility SOCP (edges at most 1 + `eps` their rest length) on `pred`.
pub fn project_socp(rest: &TriMesh, pred: &TriMesh, eps: f64) -> Result<Projected<SocpReport>> {
    let layer = InextensibilityLayer::new(rest, eps, SocpSettings::default())?;
    let x = pred.flat_positions();
    let (solution, solver) = layer.forward(&x)?;
    let y = solution.positions().to_vec();
    let timing = (solver.time_seconds, solver.iterations as usize);
    let report = report("socp", layer.rest(), (&x, &y), timing, solver)?;
    Ok((y, report))
}

/// The quasistatic spring equilibrium tied to `pred` by zero-length springs of scale `mu`.
pub fn project_quasistatic(rest: &TriMesh, pred: &TriMesh, mu: f64) -> Result<Projected<QuasistaticReport>> {
    let layer = QuasistaticLayer::new(rest, QuasistaticParams::default())?;
    let x = pred.flat_positions();
    let (solution, solver) = layer.forward(&x, &ZeroLengthScaling::Global(mu))?;
    let y = solution.positions().to_vec();
    let timing = (solver.time_seconds, solver.newton.iterations);
    let report = report("quasistatic", layer.rest(), (&x, &y), timing, solver)?;
    Ok((y, report))
}

/// Writes the projected positions `x` with the prediction's faces (format by extension).
pub fn write_projected(out: &Path, x: &[f64], pred: &TriMesh) -> Result<()> {
    let projected = TriMesh::new(weft_mesh::unflatten(x), pred.faces().to_vec())?;
    io::write_surface(out, &projected)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projections_hold_their_bound_and_report_strains() {
        let rest = weft_mesh::generators::sheet(5, 1.0).unwrap();
        let stretched: Vec<_> = rest.positions().iter().map(|p| p * 1.3).collect();
        let pred = TriMesh::new(stretched, rest.faces().to_vec()).unwrap();
        let (_, socp) = project_socp(&rest, &pred, 0.1).unwrap();
        assert!((socp.max_edge_strain_before - 0.3).abs() < 1e-9);
        assert!(
            socp.max_edge_strain_after <= 0.1 + 1e-6,
            "{}",
            socp.max_edge_strain_after
        );
        let (y, q) = project_quasistatic(&rest, &pred, 0.1).unwrap();
        assert_eq!(y.len(), 3 * rest.num_vertices());
        assert!(q.max_edge_strain_after < q.max_edge_strain_before);
    }
}
