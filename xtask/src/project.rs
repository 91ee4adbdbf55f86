//! `cargo xtask project socp|quasistatic`: run a projection layer of weft-proj on one
//! predicted mesh and print a JSON report.
//!
//! Needs (xtask/Cargo.toml): weft-mesh, weft-proj, anyhow, clap (derive), serde_json.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use weft_mesh::TriMesh;
use weft_mesh::io::{self, AnyMesh};
use weft_proj::{
    InextensibilityLayer, QuasistaticLayer, QuasistaticParams, SocpSettings, StrainSummary, ZeroLengthScaling,
    strain_summary,
};

/// Project a predicted mesh with Geng et al.'s layers.
#[derive(Debug, clap::Subcommand)]
pub enum ProjectCommand {
    /// Inextensibility SOCP: closest mass-weighted configuration with every edge at most
    /// (1 + ε) times its rest length.
    Socp {
        /// Rest mesh (a cloth surface: .obj).
        #[arg(long)]
        rest: PathBuf,
        /// Predicted mesh (.obj, same vertices and faces as REST).
        #[arg(long)]
        pred: PathBuf,
        /// Strain bound ε ≥ 0.
        #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
        eps: f64,
        /// Output mesh, format by extension (.obj, .ply, .vtk), vertex order of PRED.
        #[arg(long)]
        out: PathBuf,
    },
    /// Quasistatic spring equilibrium tied to the prediction by zero-length springs of
    /// scale μ.
    Quasistatic {
        /// Rest mesh (a cloth surface: .obj).
        #[arg(long)]
        rest: PathBuf,
        /// Predicted mesh (.obj, same vertices and faces as REST).
        #[arg(long)]
        pred: PathBuf,
        /// Zero-length spring scale μ > 0.
        #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
        mu: f64,
        /// Output mesh, format by extension (.obj, .ply, .vtk), vertex order of PRED.
        #[arg(long)]
        out: PathBuf,
    },
}

pub fn run(cmd: ProjectCommand) -> anyhow::Result<()> {
    match cmd {
        ProjectCommand::Socp { rest, pred, eps, out } => {
            let (rest_mesh, pred_mesh) = read_pair(&rest, &pred)?;
            let layer = InextensibilityLayer::new(&rest_mesh, eps, SocpSettings::default())
                .context("building the inextensibility layer")?;
            let x = pred_mesh.flat_positions();
            let (solution, report) = layer.forward(&x).context("SOCP projection")?;
            let before = strain_summary(layer.rest(), &x, 1.0)?;
            let after = strain_summary(layer.rest(), solution.positions(), 1.0)?;
            write(&out, solution.positions(), &pred_mesh)?;
            print_report(
                "socp",
                report.time_seconds,
                report.iterations as usize,
                &before,
                &after,
                serde_json::to_value(&report)?,
            )
        }
        ProjectCommand::Quasistatic { rest, pred, mu, out } => {
            let (rest_mesh, pred_mesh) = read_pair(&rest, &pred)?;
            let layer = QuasistaticLayer::new(&rest_mesh, QuasistaticParams::default())
                .context("building the quasistatic layer")?;
            let x = pred_mesh.flat_positions();
            let (solution, report) = layer
                .forward(&x, &ZeroLengthScaling::Global(mu))
                .context("quasistatic projection")?;
            let before = strain_summary(layer.rest(), &x, 1.0)?;
            let after = strain_summary(layer.rest(), solution.positions(), 1.0)?;
            write(&out, solution.positions(), &pred_mesh)?;
            print_report(
                "quasistatic",
                report.time_seconds,
                report.newton.iterations,
                &before,
                &after,
                serde_json::to_value(report)?,
            )
        }
    }
}

fn read_pair(rest: &Path, pred: &Path) -> anyhow::Result<(TriMesh, TriMesh)> {
    let surface = |path: &Path, what: &str| -> anyhow::Result<TriMesh> {
        match io::read_mesh(path).with_context(|| format!("reading {what} {}", path.display()))? {
            AnyMesh::Surface(m) => Ok(m),
            AnyMesh::Volume(_) => bail!(
                "{what} {} is a volume mesh; the projection layers take a cloth surface (.obj)",
                path.display()
            ),
        }
    };
    let rest_mesh = surface(rest, "rest mesh")?;
    let pred_mesh = surface(pred, "prediction")?;
    if rest_mesh.num_vertices() != pred_mesh.num_vertices() {
        bail!(
            "{} has {} vertices but {} has {}",
            pred.display(),
            pred_mesh.num_vertices(),
            rest.display(),
            rest_mesh.num_vertices()
        );
    }
    if rest_mesh.faces() != pred_mesh.faces() {
        bail!(
            "{} and {} have different faces; the prediction must share the rest mesh's connectivity",
            pred.display(),
            rest.display()
        );
    }
    Ok((rest_mesh, pred_mesh))
}

fn write(out: &Path, x: &[f64], pred: &TriMesh) -> anyhow::Result<()> {
    let projected = TriMesh::new(weft_mesh::unflatten(x), pred.faces().to_vec())?;
    io::write_surface(out, &projected).with_context(|| format!("writing {}", out.display()))
}

fn print_report(
    layer: &str,
    seconds: f64,
    iterations: usize,
    before: &StrainSummary,
    after: &StrainSummary,
    solver: serde_json::Value,
) -> anyhow::Result<()> {
    let report = serde_json::json!({
        "layer": layer,
        "solve_time_seconds": seconds,
        "iterations": iterations,
        "max_edge_strain_before": before.max_strain,
        "max_edge_strain_after": after.max_strain,
        // E = Σ ½ k (l − l̄)² with k = 1 N/m, split by stretched / compressed edges.
        "stretching_energy_before": before.stretching_energy,
        "stretching_energy_after": after.stretching_energy,
        "compression_energy_before": before.compression_energy,
        "compression_energy_after": after.compression_energy,
        "solver": solver,
    });
    outln!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
