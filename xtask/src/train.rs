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
    /// NNWarp's node-wise correction MLP for one material, on the `nnwarp` dataset (§5).
    Nnwarp(NnwarpArgs),
    /// Alt-ConvLSTM or one of its ConvLSTM baselines on the `limb` dataset (seed 001, §5.1).
    Altconv(AltconvArgs),
    /// Geng et al.'s pose → cloth network on the `drape` dataset, alone or trained through
    /// the inextensibility or the quasistatic layer (fixed or learned μ).
    Drape(DrapeArgs),
}

/// The layer a drape model is trained through.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DrapeLayer {
    /// The network alone (`network-only`).
    None,
    /// The inextensibility SOCP (edges at most 1 + ε their rest length).
    Socp,
    /// The quasistatic spring layer with zero-length springs of stiffness μ to the prediction.
    Quasistatic,
}

/// How μ of the quasistatic layer is learned.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum LearnMu {
    /// One μ for the whole sleeve.
    Global,
    /// One μ_i per vertex.
    PerVertex,
}

#[derive(Args)]
pub struct DrapeArgs {
    /// A `drape` dataset directory written by `cargo xtask dataset drape`.
    #[arg(long)]
    pub data: PathBuf,
    /// Where the model is written: `config.json`, `progress.json` (per epoch the training
    /// loss, validation SqrtMSE, μ and the spread of μ's gradient over batches), the
    /// checkpoints `best` and `last` (`*-mu` beside them with a learned μ) and
    /// `scores.json` (the kept model on the validation and test splits, and the second
    /// half of training: the validation error's scatter, the last μ, the strength of its
    /// gradient against its noise).
    #[arg(long)]
    pub out: PathBuf,
    /// The layer after the network, in training and in the scores.
    #[arg(long, value_enum, default_value = "none")]
    pub layer: DrapeLayer,
    /// μ of the quasistatic layer, or where a learned μ starts.
    #[arg(long, default_value_t = 0.1)]
    pub mu: f64,
    /// Learn μ (as log μ, with its own Adam at the configuration's `mu_learning_rate`).
    #[arg(long, value_enum)]
    pub learn_mu: Option<LearnMu>,
    /// A drape model directory whose best network weights training starts from (the
    /// evaluation fine-tunes every layer from `network-only`).
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// Epochs to train in all (default: the configuration's `pretrain_epochs` (200) from
    /// scratch, `finetune_epochs` (5) with --init). With --resume, a model trained for
    /// fewer epochs is continued up to this many.
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Training configuration (JSON; omitted fields keep the standard evaluation's values):
    /// `net` ({"hidden": [64, 256], "offset_scale": 0.01}), `batch` (16), `learning_rate`
    /// (1e-3), `mu_learning_rate` (0.1), `epsilon` (0.1), `quasistatic`, `seed` (1).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Continue the model in --out (same configuration, layer and --init).
    #[arg(long)]
    pub resume: bool,
    /// After training, score the kept network on the validation split with the quasistatic
    /// layer at each of these fixed μ (comma-separated, e.g. 0.01,0.1,1): the loss as a
    /// function of μ alone, written to `mu-scan.json`.
    #[arg(long, value_delimiter = ',')]
    pub scan_mu: Vec<f64>,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
}

#[derive(Args)]
pub struct AltconvArgs {
    /// A `limb` dataset directory written by `cargo xtask dataset limb`.
    #[arg(long)]
    pub data: PathBuf,
    /// The model: alt (Alt-ConvLSTM), convlstm-cp-dy, convlstm-np-dy, convlstm-cp-y or
    /// convlstm-np-y.
    #[arg(long, default_value = "alt")]
    pub model: String,
    /// Training configuration (JSON; omitted fields keep their defaults): `hidden`
    /// ([32, 64, 128, 64, 32]), `steps` (20 teacher-forced steps per sequence), `epochs`
    /// (60), `batch` (2 sequences), `adam` (lr 1e-3), `lr_decay` (0.995 per epoch), `seed`.
    /// After training, the roll-out error on the test sequences (up to 50 steps) beside
    /// skinning alone is printed and written to `scores.json`.
    #[arg(long)]
    pub config: Option<PathBuf>,
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

/// The nonlinear materials an NNWarp network is trained for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum WarpMaterial {
    CoRotational,
    Stvk,
    NeoHookean,
}

impl WarpMaterial {
    /// The dataset's array name.
    pub fn key(self) -> &'static str {
        match self {
            Self::CoRotational => "co-rotational",
            Self::Stvk => "stvk",
            Self::NeoHookean => "neo-hookean",
        }
    }
}

#[derive(Args)]
pub struct NnwarpArgs {
    /// An `nnwarp` dataset directory written by `cargo xtask dataset nnwarp`.
    #[arg(long)]
    pub data: PathBuf,
    /// The material whose registered shapes the network learns.
    #[arg(long, value_enum)]
    pub material: WarpMaterial,
    /// Training configuration (JSON; omitted fields keep their defaults): `hidden`
    /// (empty: 2 × 16, 3 × 16 for StVK), `adam`, `batch` (1024), `epochs` (10), `seed`.
    #[arg(long)]
    pub config: Option<PathBuf>,
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
        TrainCommand::Nnwarp(args) => nnwarp(args),
        TrainCommand::Altconv(args) => altconv(args),
        TrainCommand::Drape(args) => drape(args),
    }
}

fn drape(args: DrapeArgs) -> anyhow::Result<()> {
    use crate::evaluate::drape::{DrapeTrainingConfig, Layer, Layers, Plan, fit, score};
    let config: DrapeTrainingConfig = match &args.config {
        Some(p) => {
            serde_json::from_str(&std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?)
                .with_context(|| format!("parsing {}", p.display()))?
        }
        None => DrapeTrainingConfig::default(),
    };
    if config.batch == 0 {
        bail!("batch must be at least 1");
    }
    if !(args.mu > 0.0 && args.mu.is_finite()) {
        bail!("--mu must be positive and finite, not {}", args.mu);
    }
    if let Some(m) = args.scan_mu.iter().find(|m| !(**m > 0.0 && m.is_finite())) {
        bail!("--scan-mu values must be positive and finite, not {m}");
    }
    let layer = match (args.layer, args.learn_mu) {
        (DrapeLayer::None, None) => Layer::None,
        (DrapeLayer::Socp, None) => Layer::Socp,
        (DrapeLayer::Quasistatic, None) => Layer::Quasistatic(args.mu),
        (DrapeLayer::Quasistatic, Some(learn)) => Layer::LearnedMu {
            start: args.mu,
            per_vertex: learn == LearnMu::PerVertex,
        },
        (_, Some(_)) => bail!("--learn-mu needs --layer quasistatic"),
    };
    let epochs = args.epochs.unwrap_or(if args.init.is_some() {
        config.finetune_epochs
    } else {
        config.pretrain_epochs
    });
    if args.out.join("config.json").exists() && !args.resume {
        bail!(
            "{} already holds a model; pass --resume to continue it or choose another --out",
            args.out.display()
        );
    }
    let dataset =
        weft_nn::data::DrapeDataset::load(&args.data).with_context(|| format!("loading {}", args.data.display()))?;
    let device = weft_nn::Device::Cpu;
    let split = |name: &str| {
        dataset
            .tensors(name, &device)
            .with_context(|| format!("the {name} split of {}", args.data.display()))
    };
    let (train, validation, test) = (split("train")?, split("validation")?, split("test")?);
    anyhow::ensure!(
        !train.is_empty() && !validation.is_empty(),
        "{} needs training and validation examples (it has {} and {})",
        args.data.display(),
        train.len(),
        validation.len()
    );
    let v = dataset.sleeve.num_vertices();
    let layers = Layers::new(&dataset.sleeve, &config)?;
    let name = args
        .out
        .file_name()
        .map_or("model".into(), |n| n.to_string_lossy().into_owned());
    eprintln!(
        "drape/{name}: {layer}, {} training and {} validation examples on {v} vertices, {epochs} epochs",
        train.len(),
        validation.len()
    );
    let plan = Plan {
        name: &name,
        layer,
        init: args.init.as_deref(),
        epochs,
        quiet: args.quiet,
        retrain_on_mismatch: false,
    };
    let fitted = fit(&args.out, &plan, &config, &layers, &train, &validation, v)?;
    let p = &fitted.progress;
    if p.skipped_batches > 0 {
        eprintln!(
            "drape/{name}: {} training batches skipped because the layer failed on them; the first: {}",
            p.skipped_batches,
            p.first_error.clone().unwrap_or_default()
        );
    }
    if let Some(last) = p.history.last() {
        eprintln!(
            "drape/{name}: after epoch {}: training loss {:.4} mm², validation SqrtMSE {:.4} mm{}",
            p.epochs_done,
            last.loss_mm2,
            last.validation_sqrtmse_mm,
            last.mu.map_or(String::new(), |m| format!(", μ {m:.4}"))
        );
    }
    // The kept model, scored with cold solves as the evaluation scores it.
    let rest = weft_proj::RestShape::new(&dataset.sleeve)?;
    let k = config.quasistatic.stretch_stiffness;
    let mut scores = serde_json::Map::new();
    for (split, data) in [("validation", &validation), ("test", &test)] {
        if data.is_empty() {
            continue;
        }
        let (s, _) = score(&fitted.model, data, &rest, k, config.batch)?;
        eprintln!(
            "drape/{name}: kept epoch {}: {split} SqrtMSE {:.4} mm, MaxDist {:.4} mm ({} examples failed)",
            p.best_epoch.unwrap_or(0),
            s.sqrtmse,
            s.maxdist,
            s.failed
        );
        scores.insert(
            split.into(),
            serde_json::json!({
                "sqrtmse-mm": s.sqrtmse,
                "maxdist-mm": s.maxdist,
                "compression-energy-error": s.compression,
                "stretching-energy-error": s.stretching,
                "failed": s.failed,
            }),
        );
    }
    let mu = fitted
        .mu
        .as_ref()
        .map(|m| m.iter().sum::<f64>() / m.len().max(1) as f64);
    // Where training settles, over its second half: how much the validation error scatters
    // from epoch to epoch, where μ ends and how strong μ's gradient is against its noise
    // (the median over epochs of |mean| / sd of the per-batch gradient).
    let late = &p.history[p.history.len() / 2..];
    let (val_mean, val_sd) = crate::evaluate::mean_sd(late.iter().map(|h| h.validation_sqrtmse_mm));
    let mut signal: Vec<f64> = late
        .iter()
        .filter_map(|h| h.mu_gradient)
        .filter(|g| g.sd > 0.0)
        .map(|g| g.mean.abs() / g.sd)
        .collect();
    signal.sort_by(f64::total_cmp);
    let second_half = serde_json::json!({
        "epochs": [p.history.len() / 2 + 1, p.history.len()],
        "validation_sqrtmse_mm_mean": val_mean,
        "validation_sqrtmse_mm_sd": val_sd,
        "last_mu": late.last().and_then(|h| h.mu),
        "mu_gradient_mean_over_sd_median": signal.get(signal.len() / 2),
    });
    if late.len() > 1 {
        eprintln!(
            "drape/{name}: epochs {}-{}: validation SqrtMSE {val_mean:.4} ± {val_sd:.4} mm{}",
            p.history.len() / 2 + 1,
            p.history.len(),
            signal
                .get(signal.len() / 2)
                .map_or(String::new(), |s| format!(", μ gradient median |mean|/sd {s:.3}"))
        );
    }
    write_atomic(
        &args.out.join("scores.json"),
        &serde_json::to_string_pretty(&serde_json::json!({
            "kept_epoch": p.best_epoch,
            "epochs": p.epochs_done,
            "kept_mu_mean": mu,
            "second_half": second_half,
            "scores": scores,
        }))?,
    )?;
    if !args.scan_mu.is_empty() {
        // The same cold solves as the scores: the loss (mean squared SqrtMSE, mm²) and the
        // SqrtMSE of the kept network as μ alone varies.
        let mut scan = Vec::with_capacity(args.scan_mu.len());
        for &m in &args.scan_mu {
            let (s, _) = score(
                &layers.at_fixed_mu(&fitted.model.net, m),
                &validation,
                &rest,
                k,
                config.batch,
            )?;
            let loss = s.loss_mm2;
            eprintln!(
                "drape/{name}: μ = {m}: validation SqrtMSE {:.4} mm, loss {loss:.5} mm² ({} examples failed)",
                s.sqrtmse, s.failed
            );
            scan.push(serde_json::json!({
                "mu": m,
                "validation_sqrtmse_mm": s.sqrtmse,
                "validation_loss_mm2": loss,
                "failed": s.failed,
            }));
        }
        write_atomic(
            &args.out.join("mu-scan.json"),
            &serde_json::to_string_pretty(&serde_json::json!({
                "kept_epoch": p.best_epoch,
                "kept_mu_mean": mu,
                "scan": scan,
            }))?,
        )?;
    }
    eprintln!("model → {}", args.out.display());
    Ok(())
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
    swap_in(&fresh, &out.join("checkpoint"))
}

/// Replaces the directory `current` by `fresh` through renames, so that an interruption
/// leaves either the old or the new one whole (or both, as `current` and `*.old`).
fn swap_in(fresh: &Path, current: &Path) -> anyhow::Result<()> {
    let old = current.with_extension("old");
    if current.exists() {
        std::fs::rename(current, &old)?;
    }
    std::fs::rename(fresh, current)?;
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
        if !stored.trains_like(&config) {
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
    eprintln!(
        "L_phys scale: {:?} {:.4e} m²/J (inertial Δt²/m̄ {:.4e}, curvature 1/mean diag H {:.4e})",
        config.phys_scale,
        data.phys_scale(config.phys_scale),
        data.inertial_scale,
        data.curvature_scale
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

/// `cargo xtask train nnwarp`: pairs from the dataset's train and validation splits,
/// standardised on the training pairs, one checkpoint per epoch.
/// After a single-network model's epoch: its checkpoint swapped in atomically
/// (`out/checkpoint`, with the epoch count) and `log_line` appended to `out/log.csv`.
fn end_epoch(
    out: &Path,
    params: &weft_nn::params::Params,
    adam: &weft_nn::adam::Adam,
    epoch: usize,
    log_line: &str,
) -> anyhow::Result<()> {
    let fresh = out.join("checkpoint.partial");
    if fresh.exists() {
        std::fs::remove_dir_all(&fresh)?;
    }
    checkpoint::save(&fresh, params, adam, &serde_json::json!({ "epoch": epoch + 1 }))?;
    swap_in(&fresh, &out.join("checkpoint"))?;
    let mut log = std::fs::OpenOptions::new().append(true).open(out.join("log.csv"))?;
    writeln!(log, "{log_line}")?;
    Ok(())
}

fn altconv(args: AltconvArgs) -> anyhow::Result<()> {
    use weft_nn::altconv::{
        AltConvNet, AltConvTrainingConfig, Scaling, SequenceTensors, Variant, mean_error, train_epoch,
    };
    let variant = Variant::from_name(&args.model)?;
    let mut config: AltConvTrainingConfig = match &args.config {
        Some(p) => {
            serde_json::from_str(&std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?)
                .with_context(|| format!("parsing {}", p.display()))?
        }
        None => AltConvTrainingConfig::default(),
    };
    config.variant = variant;
    if config.batch == 0 || config.epochs == 0 || config.steps == 0 {
        bail!("batch, epochs and steps must be at least 1");
    }
    let ck = args.out.join("checkpoint");
    let resuming = args.resume && ck.exists();
    if ck.exists() && !args.resume {
        bail!(
            "{} already holds a model; pass --resume to continue it or choose another --out",
            args.out.display()
        );
    }
    let dataset =
        weft_nn::data::LimbDataset::load(&args.data).with_context(|| format!("loading {}", args.data.display()))?;
    let device = weft_nn::Device::Cpu;
    let tensors = |split: &str| -> anyhow::Result<Vec<SequenceTensors>> {
        dataset
            .split(split)
            .map(|s| {
                anyhow::ensure!(
                    s.skinned.len() > config.steps,
                    "sequence {} has {} frames, fewer than the {} steps trained plus the initial one",
                    s.index,
                    s.skinned.len(),
                    config.steps
                );
                Ok(SequenceTensors::new(s, config.steps + 1, &device)?)
            })
            .collect()
    };
    let train = tensors("train")?;
    let validation = tensors("validation")?;
    anyhow::ensure!(!train.is_empty(), "the dataset's train split holds no sequence");
    let adj = weft_nn::graph::NormalizedAdjacency::new(&dataset.rest)?;
    std::fs::create_dir_all(&args.out)?;
    let config_path = args.out.join("config.json");
    if resuming {
        let stored: AltConvTrainingConfig = serde_json::from_str(&std::fs::read_to_string(&config_path)?)?;
        if stored != config {
            bail!(
                "the configuration differs from the one {} was trained with; resume with the same --config",
                args.out.display()
            );
        }
    } else {
        write_atomic(&config_path, &serde_json::to_string_pretty(&config)?)?;
        let mut log = std::fs::File::create(args.out.join("log.csv"))?;
        writeln!(log, "epoch,train,validation")?;
    }
    let scaling_path = args.out.join("scaling.json");
    let scaling: Scaling = if resuming {
        serde_json::from_str(&std::fs::read_to_string(&scaling_path)?)
            .with_context(|| format!("reading {}", scaling_path.display()))?
    } else {
        let s = Scaling::fit(&train, variant, config.steps)?;
        write_atomic(&scaling_path, &serde_json::to_string_pretty(&s)?)?;
        s
    };
    let mut params = weft_nn::params::Params::new(&device, config.seed);
    let net = AltConvNet::new(&mut params, variant, &config.hidden)?.with_scaling(scaling);
    let mut adam = weft_nn::adam::Adam::new(&params, config.adam)?;
    let mut first = 0;
    if resuming {
        let state = checkpoint::load(&ck, &params, &mut adam)?;
        first = state["epoch"].as_u64().context("checkpoint lacks its epoch")? as usize;
        eprintln!("resuming after epoch {first}");
    }
    eprintln!(
        "altconv/{}: {} training and {} validation sequences of {} steps, {} vertices, {} parameters",
        variant.name(),
        train.len(),
        validation.len(),
        config.steps,
        dataset.rest.num_vertices(),
        params.num_parameters()
    );
    let batches = train.len().div_ceil(config.batch) as u64;
    let bar = progress_bar(
        args.quiet,
        (config.epochs.saturating_sub(first)) as u64 * batches,
        "altconv",
        "batches",
    )?;
    for epoch in first..config.epochs {
        let loss = train_epoch(&net, &params, &mut adam, &adj, &train, &config, epoch, |l| {
            bar.set_message(format!("epoch {epoch} loss {:.2} mm", 1e3 * l));
            bar.inc(1);
        })?;
        let val = if validation.is_empty() {
            f64::NAN
        } else {
            mean_error(&net, &adj, &validation, config.steps, true)?
        };
        end_epoch(&args.out, &params, &adam, epoch, &format!("{epoch},{loss},{val}"))?;
    }
    bar.finish_and_clear();
    // Where the model stands on unseen motions: the roll-out against skinning alone.
    let test: Vec<_> = dataset.split("test").collect();
    if let Some(frames) = test.iter().map(|s| s.skinned.len()).min() {
        let horizon = (frames - 1).min(50);
        let mut scores = serde_json::Map::new();
        for (name, model) in [("skinning", None), (variant.name(), Some(&net))] {
            let mut sum = (0.0, 0usize);
            for s in &test {
                let e = weft_nn::altconv::score_sequence(model, &adj, s, horizon)?;
                sum.0 += e.rollout.iter().flatten().sum::<f64>();
                sum.1 += e.rollout.iter().map(Vec::len).sum::<usize>();
            }
            let mm = 1e3 * sum.0 / sum.1.max(1) as f64;
            eprintln!(
                "altconv/{}: {name} roll-out error over steps 1-{horizon} of the test sequences: {mm:.3} mm",
                variant.name()
            );
            scores.insert(name.to_string(), serde_json::json!(mm));
        }
        write_atomic(
            &args.out.join("scores.json"),
            &serde_json::to_string_pretty(&serde_json::json!({ "steps": horizon, "test_rollout_mm": scores }))?,
        )?;
    }
    eprintln!("model → {}", args.out.display());
    Ok(())
}

fn nnwarp(args: NnwarpArgs) -> anyhow::Result<()> {
    use weft_nn::nnwarp::{
        Standardization, WarpMlp, WarpTrainingConfig, collect_pairs, hidden_layers, mean_loss, pair_tensors,
        train_epoch,
    };
    let mut config: WarpTrainingConfig = match &args.config {
        Some(p) => {
            serde_json::from_str(&std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?)
                .with_context(|| format!("parsing {}", p.display()))?
        }
        None => WarpTrainingConfig::default(),
    };
    if config.batch == 0 || config.epochs == 0 {
        bail!("batch and epochs must be at least 1");
    }
    let material = args.material.key();
    if !config.material.is_empty() && config.material != material {
        bail!(
            "the configuration names material {:?} but --material is {material}",
            config.material
        );
    }
    config.material = material.to_string();
    if config.hidden.is_empty() {
        config.hidden = hidden_layers(material);
    }
    let config_path = args.out.join("config.json");
    let resuming = args.resume && args.out.join("checkpoint").exists();
    if args.out.join("checkpoint").exists() && !args.resume {
        bail!(
            "{} already holds a model; pass --resume to continue it or choose another --out",
            args.out.display()
        );
    }
    let dataset = weft_nn::data::WarpDataset::load(&args.data, material)
        .with_context(|| format!("loading {}", args.data.display()))?;
    let (train_x, train_y) = collect_pairs(&dataset, "train")?;
    let (val_x, val_y) = collect_pairs(&dataset, "validation")?;
    anyhow::ensure!(!train_x.is_empty(), "the dataset's train split holds no pairs");
    std::fs::create_dir_all(&args.out)?;
    let standardization = if resuming {
        let stored: WarpTrainingConfig = serde_json::from_str(&std::fs::read_to_string(&config_path)?)?;
        if stored != config {
            bail!(
                "the configuration differs from the one {} was trained with; resume with the same --config",
                args.out.display()
            );
        }
        serde_json::from_str(&std::fs::read_to_string(args.out.join("standardization.json"))?)?
    } else {
        let s = Standardization::fit(&train_x, &train_y)?;
        write_atomic(&config_path, &serde_json::to_string_pretty(&config)?)?;
        write_atomic(
            &args.out.join("standardization.json"),
            &serde_json::to_string_pretty(&s)?,
        )?;
        let mut log = std::fs::File::create(args.out.join("log.csv"))?;
        writeln!(log, "epoch,train,validation")?;
        s
    };
    let device = weft_nn::Device::Cpu;
    let (x, y) = pair_tensors(&train_x, &train_y, &standardization, &device)?;
    let (vx, vy) = pair_tensors(&val_x, &val_y, &standardization, &device)?;
    let mut params = weft_nn::params::Params::new(&device, config.seed);
    let mlp = WarpMlp::new(&mut params, &config.hidden, &standardization)?;
    let mut adam = weft_nn::adam::Adam::new(&params, config.adam)?;
    let ck = args.out.join("checkpoint");
    let mut first = 0;
    if resuming {
        let state = checkpoint::load(&ck, &params, &mut adam)?;
        first = state["epoch"].as_u64().context("checkpoint lacks its epoch")? as usize;
        eprintln!("resuming after epoch {first}");
    }
    eprintln!(
        "nnwarp/{material}: {} training and {} validation pairs, hidden {:?}",
        train_x.len(),
        val_x.len(),
        config.hidden
    );
    let batches = train_x.len().div_ceil(config.batch) as u64;
    let bar = progress_bar(
        args.quiet,
        (config.epochs.saturating_sub(first)) as u64 * batches,
        "nnwarp",
        "batches",
    )?;
    for epoch in first..config.epochs {
        let train = train_epoch(&mlp, &params, &mut adam, &x, &y, &config, epoch, |l| {
            bar.set_message(format!("epoch {epoch} loss {l:.3e}"));
            bar.inc(1);
        })?;
        let validation = mean_loss(&mlp, &vx, &vy)?;
        end_epoch(
            &args.out,
            &params,
            &adam,
            epoch,
            &format!("{epoch},{train},{validation}"),
        )?;
    }
    bar.finish_and_clear();
    eprintln!("model → {}", args.out.display());
    Ok(())
}
