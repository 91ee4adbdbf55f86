//! weft's command line: `cargo xtask <command>`.
//!
//! Each subcommand lives in its own module and keeps its own logic thin: the library
//! crates do the work, xtask wires them together and handles files, progress and
//! reports. `cargo xtask <command> --help` documents every option.

#[macro_use]
mod out;

mod acap;
mod altconv_diagnostics;
mod dataset;
mod embed_diagnostics;
mod evaluate;
mod mesh;
mod project;
mod score;
mod simulate;
mod stability;
mod train;
mod version;
mod warp;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

/// Training allocates and frees tensors the size of the embedding's dense layers (tens of
/// MB) every step; glibc's allocator returns each to the kernel and the next one is
/// page-faulted in afresh, which cost more than the arithmetic (docs/EMBEDDING.md,
/// *Training cost*). mimalloc keeps freed memory for reuse.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

#[derive(Parser)]
#[command(
    name = "cargo xtask",
    bin_name = "cargo xtask",
    about = "weft: fast, physically faithful deformable simulation with learned models",
    // The code version a publication records (`version::code_version`), with `-dirty`
    // for a build of uncommitted code.
    version = env!("WEFT_CODE_VERSION")
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate a built-in mesh and write it (.obj, .ply, .vtk, .node), or inspect a mesh file.
    #[command(subcommand)]
    Mesh(mesh::MeshCommand),
    /// Run a cloth, volumetric or soft-tissue scene (built-in name or TOML file) and write its frames and stats.
    Simulate(simulate::SimulateArgs),
    /// ACAP features of deformed meshes (encode), meshes from features (decode), round-trip error.
    #[command(subcommand)]
    Acap(acap::AcapCommand),
    /// Project a predicted cloth onto physics: inextensibility SOCP or quasistatic springs (Geng et al.).
    #[command(subcommand)]
    Project(project::ProjectCommand),
    /// Generate a dataset of independent simulated sequences (sharded, resumable, checksummed), or merge shards.
    Dataset(dataset::DatasetArgs),
    /// Run every method against its reference and write results.json, tables.md, plots and index.html.
    Evaluate(evaluate::EvaluateArgs),
    /// Check that an evaluation's outputs exist and parse, including every record's fields (CI runs this).
    CheckReport(evaluate::CheckArgs),
    /// Sweep every simulator over extreme parameters and publish the outcome of each cell (docs/STABILITY.md).
    Stability(stability::StabilityArgs),
    /// Train a neural model on a dataset (resumable from checkpoints, progress bars with the losses).
    #[command(subcommand)]
    Train(train::TrainCommand),
    /// Score a trained model on any dataset of its kind (another seed or size) without retraining: results.json and predictions.
    Score(score::ScoreArgs),
    /// Per roll-out step and layer of a trained Alt-ConvLSTM-family model: gate means and shut shares, |C|, |Y|, gradient RMS.
    AltconvDiagnostics(altconv_diagnostics::AltconvDiagnosticsArgs),
    /// PB-loss diagnostics of the embedding (issue 71): each loss term's gradient norm on the decoder with λ_ephys calibrated from them, and the M_phys floor of PCA projections.
    #[command(subcommand)]
    EmbedDiagnostics(embed_diagnostics::EmbedDiagnosticsCommand),
    /// Run a volumetric scene as pre-factorised linear FEM corrected by a trained NNWarp network (VTK per frame).
    Warp(warp::WarpArgs),
}

/// Lets every option of `cmd` and its subcommands take a negative number as its value
/// (`--mu -1`), so that the value's own check names the problem. clap would otherwise read
/// `-1` as an unknown flag and suggest `-- -1`, which does not work for an option.
fn allow_negative_numbers(cmd: clap::Command) -> clap::Command {
    cmd.allow_negative_numbers(true).mut_subcommands(allow_negative_numbers)
}

fn main() -> anyhow::Result<()> {
    let matches = allow_negative_numbers(Cli::command()).get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    match cli.command {
        Command::Mesh(cmd) => mesh::run(cmd),
        Command::Simulate(args) => simulate::run(args),
        Command::Acap(cmd) => acap::run(cmd),
        Command::Project(cmd) => project::run(cmd),
        Command::Dataset(args) => dataset::run(args),
        Command::Evaluate(args) => evaluate::run(args),
        Command::Train(cmd) => train::run(cmd),
        Command::Score(args) => score::run(args),
        Command::AltconvDiagnostics(args) => altconv_diagnostics::run(args),
        Command::EmbedDiagnostics(cmd) => embed_diagnostics::run(cmd),
        Command::Warp(args) => warp::run(args),
        Command::CheckReport(args) => evaluate::check(args),
        Command::Stability(args) => stability::run(args),
    }
}
