//! `cargo xtask embed-diagnostics`: argument parsing for issue 71's diagnostics of the
//! embedding's PB-loss in weft-experiments (`weft_experiments::evaluate::embed::
//! gradient_log` and `mphys_floor`; docs/EMBEDDING.md, "Gradient norms and the M_phys
//! floor").

use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};
use weft_experiments::evaluate::embed::{FloorReport, GradientLog, gradient_log, mphys_floor};

#[derive(Subcommand)]
pub enum EmbedDiagnosticsCommand {
    /// Each stage-1 loss term's gradient norm on the decoder's weights at the seed's starting weights and stage 1's best and last checkpoints, and λ_ephys calibrated against the dominating term.
    Gradients(GradientsArgs),
    /// M_phys of the true test frames projected onto PCAs of the given ranks, by force (inertia, each energy term) and by region (near the grasp or not).
    Floor(FloorArgs),
}

#[derive(Args)]
pub struct GradientsArgs {
    /// A model directory written by `cargo xtask train embed` (or by the evaluation) with a trained stage 1.
    #[arg(long)]
    model: PathBuf,
    /// The cloth dataset the model trained on (`cargo xtask dataset`), read with the model's normalisation.
    #[arg(long)]
    data: PathBuf,
    /// Training windows the gradients average over, evenly spaced (default: every one).
    #[arg(long)]
    windows: Option<usize>,
    /// The calibration's target: λ_ephys ‖∇L_ephys‖ = RATIO · the largest λ_k ‖∇L_k‖ of the other terms.
    #[arg(long, default_value_t = 1.0)]
    ratio: f64,
    /// The JSON report written.
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
pub struct FloorArgs {
    /// A cloth dataset directory (`cargo xtask dataset`).
    #[arg(long)]
    data: PathBuf,
    /// PCA ranks, comma-separated (a rank beyond what the training frames span keeps them all).
    #[arg(long, value_delimiter = ',', default_values_t = [128, 256, 512, 1024])]
    ranks: Vec<usize>,
    /// "Near the grasp": within this fraction of the rest mesh's bounding-box diagonal of a grasped vertex.
    #[arg(long, default_value_t = 0.1)]
    near: f64,
    /// The JSON report written.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(cmd: EmbedDiagnosticsCommand) -> anyhow::Result<()> {
    match cmd {
        EmbedDiagnosticsCommand::Gradients(args) => {
            anyhow::ensure!(args.windows != Some(0), "--windows must be at least 1");
            let log = gradient_log(&args.model, &args.data, args.windows, args.ratio)?;
            write(&args.out, &log)?;
            print_gradients(&log);
        }
        EmbedDiagnosticsCommand::Floor(args) => {
            let report = mphys_floor(&args.data, &args.ranks, args.near)?;
            write(&args.out, &report)?;
            print_floor(&report);
        }
    }
    Ok(())
}

fn write(path: &Path, value: &impl serde::Serialize) -> anyhow::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(path, serde_json::to_string_pretty(value)?)?;
    eprintln!("diagnostics → {}", path.display());
    Ok(())
}

fn print_gradients(log: &GradientLog) {
    outln!(
        "{}: λ_ephys {} (L_phys scale {:.3e} m²/J), gradients on the decoder",
        log.scene,
        log.ephys_weight,
        log.phys_scale
    );
    for c in &log.checkpoints {
        let terms: Vec<String> = c
            .norms
            .terms
            .iter()
            .map(|t| format!("{} {:.3e} (λ·‖∇‖ {:.3e})", t.term, t.norm, t.weighted_norm))
            .collect();
        outln!("{} (epoch {}): ‖∇L‖ {}", c.checkpoint, c.epoch, terms.join(", "));
        outln!(
            "  λ_ephys for {} × {}'s: {:.4e}",
            c.calibration.ratio,
            c.calibration.dominant,
            c.calibration.ephys_weight
        );
    }
}

fn print_floor(r: &FloorReport) {
    outln!(
        "{}: {} training frames, {} scored test frames; near the grasp: {} vertices within {:.4} m, {} beyond",
        r.scene,
        r.training_frames,
        r.scored_frames,
        r.near_vertices,
        r.near_radius_m,
        r.far_vertices
    );
    for row in &r.rows {
        let rank = row
            .rank
            .map_or("truth".to_string(), |k| format!("{k} ({})", row.components));
        outln!(
            "rank {rank}: M_rms {:.4} mm, M_phys {:.4e} N² (near {:.4e}, far {:.4e})",
            row.m_rms_mm,
            row.m_phys,
            row.near.total,
            row.far.total
        );
    }
}
