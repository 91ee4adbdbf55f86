//! `cargo xtask stability`: argument parsing for weft-experiments' stability map
//! (docs/STABILITY.md).

use std::path::PathBuf;

use clap::Args;

#[derive(Args)]
pub struct StabilityArgs {
    /// The small grid CI runs (coarse meshes, three values per axis).
    #[arg(long)]
    quick: bool,
    /// Output directory: results.json (tidy records), cells.json (every cell with its error
    /// message), stability.md, and heat maps under plots/.
    #[arg(long, default_value = "out/stability")]
    out: PathBuf,
    /// Hide the progress bar.
    #[arg(long)]
    quiet: bool,
}

pub fn run(args: StabilityArgs) -> anyhow::Result<()> {
    weft_experiments::stability::run(&weft_experiments::stability::StabilityOptions {
        quick: args.quick,
        out: args.out,
        quiet: args.quiet,
    })?;
    Ok(())
}
