//! `cargo xtask altconv-diagnostics`: argument parsing for weft-nn's diagnostics of a
//! trained Alt-ConvLSTM-family model's roll-out (`weft_nn::altconv::diagnose_model`).

use std::path::PathBuf;

use clap::Args;

#[derive(Args)]
pub struct AltconvDiagnosticsArgs {
    /// A model directory written by `cargo xtask train altconv` (or by the evaluation).
    #[arg(long)]
    model: PathBuf,
    /// A `limb` or `limb-jiggle` dataset directory (`cargo xtask dataset`).
    #[arg(long)]
    data: PathBuf,
    /// The split rolled out: train, validation or test.
    #[arg(long, default_value = "validation")]
    split: String,
    /// Roll-out steps (at most the shortest sequence's frames less one).
    #[arg(long, default_value_t = 50)]
    steps: usize,
    /// The JSON report written (per step and layer; per layer gradient RMS).
    #[arg(long)]
    out: PathBuf,
}

pub fn run(args: AltconvDiagnosticsArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.steps >= 1, "--steps must be at least 1");
    let report = weft_nn::altconv::diagnose_model(&args.model, &args.data, &args.split, args.steps)?;
    report.write(&args.out)?;
    for line in report.table().lines() {
        outln!("{line}");
    }
    eprintln!("diagnostics → {}", args.out.display());
    Ok(())
}
