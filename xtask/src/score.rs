//! `cargo xtask score`: argument parsing for weft-experiments' scoring of a trained model on
//! any dataset of its kind.

use std::path::PathBuf;

use clap::Args;
use weft_experiments::score::{ModelKind, ScoreOptions};

#[derive(Args)]
pub struct ScoreArgs {
    /// The model's kind: embed, nnwarp, altconv or drape.
    kind: ModelKind,
    /// A model directory written by `cargo xtask train` (or by the evaluation).
    #[arg(long)]
    model: PathBuf,
    /// A dataset directory of the model's kind (`cargo xtask dataset`), of any seed or size.
    #[arg(long)]
    data: PathBuf,
    /// The split scored: train, validation or test (embed: test, Tan et al.'s test frames,
    /// or validation, its windows with M_phys split into its inertial and potential forces).
    #[arg(long, default_value = "test")]
    split: String,
    /// Where results.json (tidy records, docs/RESULTS.md) and predictions/ are written.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: ScoreArgs) -> anyhow::Result<()> {
    let output = weft_experiments::score::score(&ScoreOptions {
        kind: args.kind,
        model: args.model,
        data: args.data,
        split: args.split,
        out: args.out.clone(),
    })?;
    for r in &output.records {
        outln!(
            "{}/{}/{} {} ({}): {:.6} {}",
            r.experiment,
            r.scene,
            r.method,
            r.metric,
            r.split.as_deref().unwrap_or("-"),
            r.value,
            r.unit
        );
    }
    for f in &output.failures {
        eprintln!("warning: {f}");
    }
    eprintln!("results → {}", args.out.join("results.json").display());
    Ok(())
}
