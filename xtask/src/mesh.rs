//! `cargo xtask mesh`: generate built-in meshes, inspect mesh files.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, Subcommand};
use weft_mesh::generators::{self, BeamParams};
use weft_mesh::info::MeshFileReport;
use weft_mesh::io::AnyMesh;

#[derive(Subcommand)]
pub enum MeshCommand {
    /// Square n×n vertex grid in the XY plane (65 → 4225 vertices, Tan et al.'s SHEET).
    Sheet {
        /// Vertices per side.
        #[arg(long, default_value_t = 65)]
        n: usize,
        /// Side length (m).
        #[arg(long, default_value_t = 1.0)]
        size: f64,
        #[command(flatten)]
        out: Out,
    },
    /// The 65-grid sheet with two circular holes (4165 vertices).
    SheetHoles {
        /// Side length (m).
        #[arg(long, default_value_t = 1.0)]
        size: f64,
        #[command(flatten)]
        out: Out,
    },
    /// Closed UV sphere (48 segments × 32 rings + 2 poles = 1538 vertices, Tan et al.'s BALL).
    Ball {
        /// Vertices around each ring of latitude.
        #[arg(long, default_value_t = 48)]
        segments: usize,
        /// Rings of latitude between the two poles.
        #[arg(long, default_value_t = 32)]
        rings: usize,
        /// Radius (m).
        #[arg(long, default_value_t = 0.5)]
        radius: f64,
        #[command(flatten)]
        out: Out,
    },
    /// Tetrahedral box beam (default 12×6×6 cells, 2592 tets; NNWarp's training beam analogue).
    Beam {
        #[command(flatten)]
        beam: BeamArgs,
        #[command(flatten)]
        out: Out,
    },
    /// Beam whose cross-section shrinks linearly to `--tip-scale` at its free end.
    TaperedBeam {
        #[command(flatten)]
        beam: BeamArgs,
        /// The free end's cross-section as a fraction of the fixed end's (positive).
        #[arg(long, default_value_t = 0.5)]
        tip_scale: f64,
        #[command(flatten)]
        out: Out,
    },
    /// Beam bent along a circular arc by `--angle` radians.
    BentBeam {
        #[command(flatten)]
        beam: BeamArgs,
        /// Bend angle (radians, positive; the arc's inner radius must stay positive).
        #[arg(long, default_value_t = std::f64::consts::FRAC_PI_2)]
        angle: f64,
        #[command(flatten)]
        out: Out,
    },
    /// Beam with a T-shaped cross-section.
    TBeam {
        #[command(flatten)]
        beam: BeamArgs,
        #[command(flatten)]
        out: Out,
    },
    /// Print counts and validation results of a mesh file (.obj, .ply, .vtk, .node/.ele) as JSON.
    Info {
        /// The mesh file.
        file: PathBuf,
    },
}

#[derive(Args)]
pub struct Out {
    /// Output file; the format follows the extension: .obj, .ply, .vtk, or .node (TetGen .node + .ele, tet meshes only).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
pub struct BeamArgs {
    /// Cells along X, Y, Z (each cell is split into 6 tetrahedra).
    #[arg(long, num_args = 3, value_names = ["NX", "NY", "NZ"], default_values_t = [12, 6, 6])]
    cells: Vec<usize>,
    /// Size along X, Y, Z (m).
    #[arg(long, num_args = 3, value_names = ["LX", "LY", "LZ"], default_values_t = [1.0, 0.5, 0.5])]
    size: Vec<f64>,
}

impl BeamArgs {
    fn params(&self) -> BeamParams {
        BeamParams {
            cells: [self.cells[0], self.cells[1], self.cells[2]],
            size: [self.size[0], self.size[1], self.size[2]],
        }
    }
}

pub fn run(cmd: MeshCommand) -> anyhow::Result<()> {
    let (mesh, out) = match cmd {
        MeshCommand::Info { file } => return info(&file),
        MeshCommand::Sheet { n, size, out } => (AnyMesh::Surface(generators::sheet(n, size)?), out),
        MeshCommand::SheetHoles { size, out } => (
            AnyMesh::Surface(generators::sheet_with_holes(65, size, &generators::DEFAULT_HOLES)?),
            out,
        ),
        MeshCommand::Ball {
            segments,
            rings,
            radius,
            out,
        } => (AnyMesh::Surface(generators::ball(segments, rings, radius)?), out),
        MeshCommand::Beam { beam, out } => (AnyMesh::Volume(generators::beam(&beam.params())?), out),
        MeshCommand::TaperedBeam { beam, tip_scale, out } => (
            AnyMesh::Volume(generators::tapered_beam(&beam.params(), tip_scale)?),
            out,
        ),
        MeshCommand::BentBeam { beam, angle, out } => {
            (AnyMesh::Volume(generators::bent_beam(&beam.params(), angle)?), out)
        }
        MeshCommand::TBeam { beam, out } => (AnyMesh::Volume(generators::t_beam(&beam.params())?), out),
    };
    mesh.write(&out.out)
        .with_context(|| format!("writing {}", out.out.display()))?;
    eprintln!("wrote {} ({})", out.out.display(), mesh.counts());
    Ok(())
}

fn info(file: &Path) -> anyhow::Result<()> {
    let report = MeshFileReport::read(file)?;
    // Through a JSON value, whose keys are sorted, as the report has always been printed.
    outln!("{}", serde_json::to_string_pretty(&serde_json::to_value(&report)?)?);
    if let Some(e) = &report.error {
        anyhow::bail!(
            "{} is not a valid mesh: {}",
            file.display(),
            serde_json::Value::from(e.as_str())
        );
    }
    Ok(())
}
