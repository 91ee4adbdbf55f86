//! `cargo xtask project socp|quasistatic`: run a projection layer of weft-proj on one
//! predicted mesh and print a JSON report.

use std::path::PathBuf;

use anyhow::Context;
use weft_proj::files::{project_quasistatic, project_socp, read_rest_and_prediction, write_projected};

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
    let report = match cmd {
        ProjectCommand::Socp { rest, pred, eps, out } => {
            let (rest_mesh, pred_mesh) = read_rest_and_prediction(&rest, &pred)?;
            let (x, report) = project_socp(&rest_mesh, &pred_mesh, eps).context("SOCP projection")?;
            write_projected(&out, &x, &pred_mesh).with_context(|| format!("writing {}", out.display()))?;
            serde_json::to_value(report)?
        }
        ProjectCommand::Quasistatic { rest, pred, mu, out } => {
            let (rest_mesh, pred_mesh) = read_rest_and_prediction(&rest, &pred)?;
            let (x, report) = project_quasistatic(&rest_mesh, &pred_mesh, mu).context("quasistatic projection")?;
            write_projected(&out, &x, &pred_mesh).with_context(|| format!("writing {}", out.display()))?;
            serde_json::to_value(report)?
        }
    };
    // Through a JSON value, whose keys are sorted, as the report has always been printed.
    outln!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
