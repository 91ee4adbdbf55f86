//! `cargo xtask dataset`: argument parsing for weft-data's generator (`docs/DATASETS.md`).

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use weft_data::generate_all::{default_out, generate_complete, generate_every, size_table, spec_with_counts};
use weft_data::{DatasetSpec, GenerateOptions, Shard, Size};

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

    fn spec(&self, name: &str) -> weft_data::Result<DatasetSpec> {
        spec_with_counts(name, self.size, self.sequences, self.frames)
    }
}

pub fn run(args: DatasetArgs) -> anyhow::Result<()> {
    let g = match args.command {
        Some(DatasetCommand::Merge(m)) => return weft_data::merge(&m.out, &m.shards).map(|_| ()).map_err(Into::into),
        Some(DatasetCommand::List) => {
            for line in size_table()? {
                outln!("{line}");
            }
            return Ok(());
        }
        None => args.generate,
    };
    let name = g
        .name
        .clone()
        .context("name a dataset (or `all`); `cargo xtask dataset list` shows them")?;
    let out = g.out.clone().unwrap_or_else(|| default_out(&name, g.size));
    if name == "all" {
        // One failing dataset does not stop the others; every failure is reported.
        generate_every(
            &out,
            &g.options(),
            |d| g.spec(d),
            |d, e| eprintln!("{d}: {:#}", anyhow::Error::from(e)),
        )?;
    } else {
        generate_complete(&g.spec(&name)?, &out, &g.options())?;
    }
    Ok(())
}
