//! `cargo xtask train`: training the neural models on pipeline datasets.
//!
//! A model directory holds `config.json` (the training configuration), `normalization.json`
//! (the ACAP feature normalisation, fitted on the training frames), `checkpoint/` (the
//! latest epoch: both networks' parameters and optimiser states and `progress.json`) and
//! `log.csv` (mean losses per epoch). A checkpoint is written after every epoch into a
//! fresh directory that then replaces the old one by a rename, so an interrupted run
//! resumes (`--resume`) from its last complete epoch and continues bit for bit.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use weft_nn::checkpoint;
use weft_nn::data::ClothDataset;
use weft_nn::embed_training::{
    EmbedData, EmbedModel, EmbedTrainingConfig, LossTerms, Progress, optimizers, train_epoch,
};

use crate::output::progress_bar;

#[derive(Subcommand)]
pub enum TrainCommand {
    /// Tan et al.'s mesh embedding and latent simulator, in three stages (§VI-A).
    Embed(EmbedArgs),
}

#[derive(Args)]
pub struct EmbedArgs {
    /// A cloth dataset directory written by `cargo xtask dataset`.
    #[arg(long)]
    pub data: PathBuf,
    /// Training configuration (JSON; any field omitted keeps its default). Defaults:
    /// 2 graph convolutions, 128-D latent, λ = (recon 1, vert 1, ephys 0.5, sim 1,
    /// mphys 0.5), Adam lr 1e-3, batch 8, epochs [30, 30, 10], seed 0.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The "[46] + L_vert" baseline: λ_ephys = λ_mphys = 0 (overrides the configuration).
    #[arg(long)]
    pub no_pb: bool,
    /// Stages to run, e.g. `1,2,3` (default) or `2,3` to continue a trained autoencoder.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
    pub stages: Vec<u8>,
    /// Where the model is written.
    #[arg(long)]
    pub out: PathBuf,
    /// Continue from the model directory's last checkpoint.
    #[arg(long)]
    pub resume: bool,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
}

pub fn run(cmd: TrainCommand) -> anyhow::Result<()> {
    match cmd {
        TrainCommand::Embed(args) => embed(args),
    }
}

fn read_config(args: &EmbedArgs) -> anyhow::Result<EmbedTrainingConfig> {
    let mut config = match &args.config {
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            serde_json::from_str(&text).with_context(|| format!("parsing {}", p.display()))?
        }
        None => EmbedTrainingConfig::default(),
    };
    if args.no_pb {
        config.weights.ephys = 0.0;
        config.weights.mphys = 0.0;
    }
    if config.batch == 0 {
        bail!("batch must be at least 1");
    }
    Ok(config)
}

fn write_atomic(path: &Path, text: &str) -> anyhow::Result<()> {
    let tmp = path.with_extension("partial");
    std::fs::write(&tmp, text).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming into {}", path.display()))
}

/// Saves both networks and `progress` as `out/checkpoint`, replacing the previous one by
/// a directory rename.
fn save_checkpoint(
    out: &Path,
    model: &EmbedModel,
    adams: (&weft_nn::adam::Adam, &weft_nn::adam::Adam),
    progress: Progress,
) -> anyhow::Result<()> {
    let fresh = out.join("checkpoint.partial");
    if fresh.exists() {
        std::fs::remove_dir_all(&fresh)?;
    }
    // `progress.json` is the one record of where training stands.
    let none = serde_json::Value::Null;
    checkpoint::save(&fresh.join("autoencoder"), &model.autoencoder_params, adams.0, &none)?;
    checkpoint::save(&fresh.join("simulator"), &model.simulator_params, adams.1, &none)?;
    write_atomic(&fresh.join("progress.json"), &serde_json::to_string_pretty(&progress)?)?;
    let current = out.join("checkpoint");
    let old = out.join("checkpoint.old");
    if current.exists() {
        std::fs::rename(&current, &old)?;
    }
    std::fs::rename(&fresh, &current)?;
    if old.exists() {
        std::fs::remove_dir_all(&old)?;
    }
    Ok(())
}

fn embed(args: EmbedArgs) -> anyhow::Result<()> {
    let config = read_config(&args)?;
    if let Some(&s) = args.stages.iter().find(|s| !(1..=3).contains(*s)) {
        bail!("stage {s} does not exist (stages are 1, 2 and 3)");
    }
    let config_path = args.out.join("config.json");
    if args.out.join("checkpoint").exists() && !args.resume {
        bail!(
            "{} already holds a model; pass --resume to continue it or choose another --out",
            args.out.display()
        );
    }
    std::fs::create_dir_all(&args.out)?;
    let dataset = ClothDataset::load(&args.data).with_context(|| format!("loading {}", args.data.display()))?;
    let name = dataset.name.clone();
    let data = EmbedData::new(dataset)?;
    let mut model = EmbedModel::new(config.clone(), &data)?;
    let (mut ae_adam, mut sim_adam) = optimizers(&model, config.adam)?;
    let mut start = Progress {
        stage: *args.stages.first().unwrap_or(&1),
        epoch: 0,
    };
    if args.resume && args.out.join("checkpoint").exists() {
        let stored: EmbedTrainingConfig = serde_json::from_str(&std::fs::read_to_string(&config_path)?)?;
        if stored != config {
            bail!(
                "the configuration differs from the one {} was trained with; resume with the same --config and flags",
                args.out.display()
            );
        }
        let ck = args.out.join("checkpoint");
        checkpoint::load(&ck.join("autoencoder"), &model.autoencoder_params, &mut ae_adam)?;
        checkpoint::load(&ck.join("simulator"), &model.simulator_params, &mut sim_adam)?;
        start = serde_json::from_str(&std::fs::read_to_string(ck.join("progress.json"))?)?;
        eprintln!("resuming at stage {}, epoch {}", start.stage, start.epoch);
    } else {
        write_atomic(&config_path, &serde_json::to_string_pretty(&config)?)?;
        write_atomic(
            &args.out.join("normalization.json"),
            &serde_json::to_string_pretty(&data.normalization)?,
        )?;
        let mut log = std::fs::File::create(args.out.join("log.csv"))?;
        writeln!(log, "stage,epoch,recon,vert,ephys,sim,mphys,total")?;
    }
    model.config = config.clone();
    eprintln!(
        "{name}: {} training windows, {} vertices, {} + {} parameters",
        data.train_windows.len(),
        data.num_vertices(),
        model.autoencoder_params.num_parameters(),
        model.simulator_params.num_parameters()
    );
    for &stage in &args.stages {
        if stage < start.stage {
            continue;
        }
        let epochs = config.epochs[stage as usize - 1];
        let first = if stage == start.stage { start.epoch } else { 0 };
        let batches = data.train_windows.len().div_ceil(config.batch) as u64;
        let bar = progress_bar(
            args.quiet,
            (epochs - first.min(epochs)) as u64 * batches,
            &format!("stage {stage}"),
            "batches",
        )?;
        for epoch in first..epochs {
            let progress = Progress { stage, epoch };
            let mean = train_epoch(
                &model,
                &data,
                (&mut ae_adam, &mut sim_adam),
                progress,
                |t: &LossTerms| {
                    bar.set_message(format!(
                        "recon {:.3e} vert {:.3e} ephys {:.3e} sim {:.3e} mphys {:.3e}",
                        t.recon, t.vert, t.ephys, t.sim, t.mphys
                    ));
                    bar.inc(1);
                },
            )?;
            save_checkpoint(
                &args.out,
                &model,
                (&ae_adam, &sim_adam),
                Progress {
                    stage,
                    epoch: epoch + 1,
                },
            )?;
            let mut log = std::fs::OpenOptions::new()
                .append(true)
                .open(args.out.join("log.csv"))?;
            writeln!(
                log,
                "{stage},{epoch},{},{},{},{},{},{}",
                mean.recon, mean.vert, mean.ephys, mean.sim, mean.mphys, mean.total
            )?;
        }
        bar.finish_and_clear();
        // The next stage starts at its first epoch.
        start = Progress {
            stage: stage + 1,
            epoch: 0,
        };
    }
    eprintln!("model → {}", args.out.display());
    Ok(())
}
