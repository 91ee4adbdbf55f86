//! `cargo xtask dataset`: argument parsing for weft-data's generator (`docs/DATASETS.md`).

use std::path::PathBuf;

use anyhow::{Context, bail, ensure};
use clap::{Args, Subcommand};
use weft_data::{DatasetSpec, GenerateOptions, Shard, Size, dataset_names};

#[derive(Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct DatasetArgs {
    #[command(subcommand)]
    command: Option<DatasetCommand>,
    #[command(flatten)]
    generate: GenerateArgs,
}

#[derive(Subcommand)]
enum DatasetCommand {
    /// Join the shards of one dataset (from one or more directories) into OUT, verifying every checksum.
    Merge(MergeArgs),
    /// List the datasets with their sequence and frame counts at each size.
    List,
}

#[derive(Args)]
pub struct GenerateArgs {
    /// Dataset name — a built-in cloth scene, limb, limb-jiggle, nnwarp, drape or drape-loose — or `all`.
    /// `cargo xtask dataset list` shows them with their sizes.
    name: Option<String>,
    /// quick (seconds), standard (the committed evaluation's), or paper (the papers' sizes).
    #[arg(long, default_value_t = Size::Quick)]
    size: Size,
    /// Output directory (default: data/<name>-<size>; with `all`, one subdirectory per dataset).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Compute only slice i of n (0-based), e.g. `--shard 2/8`; join the slices with `dataset merge`.
    #[arg(long)]
    shard: Option<Shard>,
    /// Continue an interrupted run in OUT: sequences already written (and matching their checksums) are kept.
    #[arg(long)]
    resume: bool,
    /// Dataset seed; sequence i's seed is derived from (seed, i).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Override the size's number of sequences.
    #[arg(long)]
    sequences: Option<usize>,
    /// Override the size's frames per sequence.
    #[arg(long)]
    frames: Option<usize>,
    /// Hide the progress bar.
    #[arg(long)]
    quiet: bool,
}

#[derive(Args)]
struct MergeArgs {
    /// Directory to write the merged dataset to (it may be one of the shard directories).
    #[arg(long)]
    out: PathBuf,
    /// Directories holding `manifest-shard-<i>-of-<n>.json` files and their sequences.
    #[arg(required = true)]
    shards: Vec<PathBuf>,
}

impl GenerateArgs {
    fn options(&self) -> GenerateOptions {
        GenerateOptions {
            shard: self.shard,
            resume: self.resume,
            seed: self.seed,
            quiet: self.quiet,
            code_version: crate::version::code_version(),
        }
    }

    fn spec(&self, name: &str) -> anyhow::Result<DatasetSpec> {
        let mut spec = DatasetSpec::new(name, self.size)?;
        if let Some(n) = self.sequences {
            ensure!(n > 0, "--sequences must be at least 1");
            spec.sequences = n;
        }
        if let Some(f) = self.frames {
            ensure!(f > 0, "--frames must be at least 1");
            spec.frames = f;
        }
        Ok(spec)
    }
}

pub fn run(args: DatasetArgs) -> anyhow::Result<()> {
    match args.command {
        Some(DatasetCommand::Merge(m)) => weft_data::merge(&m.out, &m.shards).map(|_| ()).map_err(Into::into),
        Some(DatasetCommand::List) => list(),
        None => {
            let g = args.generate;
            let name = g
                .name
                .clone()
                .context("name a dataset (or `all`); `cargo xtask dataset list` shows them")?;
            let options = g.options();
            if name == "all" {
                let root = g
                    .out
                    .clone()
                    .unwrap_or_else(|| PathBuf::from(format!("data/{}", g.size.as_str())));
                // One failing dataset does not stop the others; every failure is reported.
                let mut failed = Vec::new();
                for d in dataset_names() {
                    if let Err(e) = generate(&g.spec(d)?, &root.join(d), &options) {
                        eprintln!("{d}: {e:#}");
                        failed.push(d);
                    }
                }
                if !failed.is_empty() {
                    bail!("{} dataset(s) failed: {}", failed.len(), failed.join(", "));
                }
                Ok(())
            } else {
                let spec = g.spec(&name)?;
                let out = g
                    .out
                    .clone()
                    .unwrap_or_else(|| PathBuf::from(format!("data/{name}-{}", g.size.as_str())));
                generate(&spec, &out, &options)
            }
        }
    }
}

/// Generates a dataset; sequences that stopped early (stored up to the failure) make the
/// command fail after everything else is written.
fn generate(spec: &DatasetSpec, out: &std::path::Path, options: &GenerateOptions) -> anyhow::Result<()> {
    let stopped = weft_data::generate(spec, out, options)?.stopped_early();
    if !stopped.is_empty() {
        bail!(
            "{} sequence(s) stopped early (their frames up to the failure are stored): {}",
            stopped.len(),
            stopped.join("; ")
        );
    }
    Ok(())
}

fn list() -> anyhow::Result<()> {
    outln!("{:<24} {:>22} {:>22} {:>22}", "dataset", "quick", "standard", "paper");
    for d in dataset_names() {
        let cell = |s| -> anyhow::Result<String> {
            let spec = DatasetSpec::new(d, s)?;
            Ok(format!("{} × {} frames", spec.sequences, spec.frames))
        };
        outln!(
            "{d:<24} {:>22} {:>22} {:>22}",
            cell(Size::Quick)?,
            cell(Size::Standard)?,
            cell(Size::Paper)?
        );
    }
    Ok(())
}
