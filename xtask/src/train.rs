//! `cargo xtask train`: argument parsing for training weft-nn's models on pipeline
//! datasets. Every model trains through `weft_nn::trainer::Trainer` (one epoch loop,
//! validation-only model selection, a checkpoint each epoch, bit-identical resume); the
//! drivers that read a dataset and write a model directory are weft-nn's `train_model`
//! functions. A model directory holds the configuration, what was fitted on the training
//! split (normalisation, scaling, standardisation) and the trainer's run: `training.json`,
//! `train.log`, `best/` and `last/` checkpoints.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};

use weft_nn::progress::TrainProgress;
use weft_nn::train_setup::{
    DrapeLayerKind, Overrides, altconv_config, drape_config, drape_layer, embed_config, fit_altconv_steps,
    nnwarp_config, refuse_overwrite, sets_field,
};

#[derive(Subcommand)]
pub enum TrainCommand {
    /// Tan et al.'s mesh embedding and latent simulator, in three stages (§VI-A).
    #[command(after_help = weft_nn::config_help::EMBED)]
    Embed(EmbedArgs),
    /// NNWarp's node-wise correction MLP for one material, on the `nnwarp` dataset (§5).
    #[command(after_help = weft_nn::config_help::NNWARP)]
    Nnwarp(NnwarpArgs),
    /// Alt-ConvLSTM or one of its ConvLSTM baselines on the `limb` dataset (seed 001, §5.1).
    #[command(after_help = weft_nn::config_help::ALTCONV)]
    Altconv(AltconvArgs),
    /// Geng et al.'s pose → cloth network on a drape dataset (`drape` or `drape-loose`), alone or trained through
    /// the inextensibility or the quasistatic layer (fixed or learned μ).
    #[command(after_help = weft_nn::config_help::DRAPE)]
    Drape(DrapeArgs),
}

/// Flags every `train` command takes.
#[derive(Args, Clone, Default)]
pub struct TrainArgs {
    /// Training configuration (JSON; the fields are listed below).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Epochs (overrides the configuration; for `embed`, of every stage run). With
    /// --resume, a model trained for fewer epochs is continued up to this many.
    #[arg(long)]
    pub epochs: Option<usize>,
    /// Seed of the initial weights and the epoch order (overrides the configuration).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Base learning rate (overrides the configuration).
    #[arg(long)]
    pub lr: Option<f64>,
    /// Continue the model in --out (same configuration; the epochs and the early-stopping
    /// patience may grow: a run that stopped early goes on under a longer patience).
    #[arg(long)]
    pub resume: bool,
    /// No progress bars and no epoch lines (they are in the model's train.log).
    #[arg(long)]
    pub quiet: bool,
    /// Train through candle's autograd, the reference, instead of the fused kernels with
    /// hand-written backward passes (same results to f32 round-off, several times slower).
    #[arg(long)]
    pub autograd: bool,
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
    /// A drape dataset directory written by `cargo xtask dataset drape` (or `drape-loose`).
    #[arg(long)]
    pub data: PathBuf,
    /// Where the model is written: `config.json`, the trainer's run (`training.json`: per
    /// epoch the training loss, validation SqrtMSE, μ and the spread of μ's gradient over
    /// batches; `best/`, `last/`, `train.log`) and `scores.json` (the kept model on the
    /// validation and test splits, and the second half of training: the validation
    /// error's scatter, the last μ, the strength of its gradient against its noise).
    #[arg(long)]
    pub out: PathBuf,
    /// The layer after the network, in training and in the scores.
    #[arg(long, value_enum, default_value = "none")]
    pub layer: DrapeLayer,
    /// μ of the quasistatic layer, or where a learned μ starts [default: 0.1]. Only with
    /// `--layer quasistatic`.
    #[arg(long)]
    pub mu: Option<f64>,
    /// Learn μ (as log μ, with its own Adam at the configuration's `mu_learning_rate`).
    #[arg(long, value_enum)]
    pub learn_mu: Option<LearnMu>,
    /// A drape model directory whose best network weights training starts from (the
    /// evaluation fine-tunes every layer from `network-only`). Epochs default to the
    /// configuration's `finetune_epochs` with it, `pretrain_epochs` without.
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// After training, score the kept network on the validation split with the quasistatic
    /// layer at each of these fixed μ (comma-separated, e.g. 0.01,0.1,1): the loss as a
    /// function of μ alone, written to `mu-scan.json`.
    #[arg(long, value_delimiter = ',')]
    pub scan_mu: Vec<f64>,
    /// Train on the first N training examples only (a data-size study); validation and
    /// test stay whole.
    #[arg(long)]
    pub train_examples: Option<usize>,
    #[command(flatten)]
    pub common: TrainArgs,
}

#[derive(Args)]
pub struct AltconvArgs {
    /// A `limb` dataset directory written by `cargo xtask dataset limb`.
    #[arg(long)]
    pub data: PathBuf,
    /// The model: alt (Alt-ConvLSTM), convlstm-cp-dy, convlstm-np-dy, convlstm-cp-y or
    /// convlstm-np-y. After training, the roll-out error on the validation sequences (up
    /// to 50 steps) beside skinning alone is printed and written to `scores.json`.
    #[arg(long, default_value = "alt")]
    pub model: String,
    /// Where the model is written.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub common: TrainArgs,
}

#[derive(Args)]
pub struct NnwarpArgs {
    /// An `nnwarp` dataset directory written by `cargo xtask dataset nnwarp`.
    #[arg(long)]
    pub data: PathBuf,
    /// The material whose registered shapes the network learns.
    #[arg(long, value_parser = warp_materials())]
    pub material: String,
    /// Where the model is written.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub common: TrainArgs,
}

#[derive(Args)]
pub struct EmbedArgs {
    /// A cloth dataset directory written by `cargo xtask dataset`.
    #[arg(long)]
    pub data: PathBuf,
    /// The "[46] + L_vert" baseline: λ_ephys = λ_mphys = 0 (overrides the configuration).
    #[arg(long)]
    pub no_pb: bool,
    /// Stages to run, e.g. `1,2,3` (default) or `2,3` to continue a trained autoencoder.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
    pub stages: Vec<u8>,
    /// Where the model is written.
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub common: TrainArgs,
}

/// The materials an NNWarp network is trained for, by their dataset keys.
fn warp_materials() -> clap::builder::PossibleValuesParser {
    use weft_sim::energies::Material;
    [Material::CoRotational, Material::StVK, Material::NeoHookean]
        .map(weft_data::nnwarp::material_key)
        .into()
}

impl TrainArgs {
    fn overrides(&self) -> Overrides {
        Overrides {
            seed: self.seed,
            learning_rate: self.lr,
            epochs: self.epochs,
        }
    }
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
    use weft_nn::drape::DrapeRun;
    use weft_nn::drape::Plan;
    let c = &args.common;
    let config = drape_config(c.config.as_deref(), &c.overrides())?;
    let kind = match args.layer {
        DrapeLayer::None => DrapeLayerKind::None,
        DrapeLayer::Socp => DrapeLayerKind::Socp,
        DrapeLayer::Quasistatic => DrapeLayerKind::Quasistatic,
    };
    let learn_mu = args.learn_mu.map(|l| l == LearnMu::PerVertex);
    let layer = drape_layer(kind, args.mu, learn_mu, &args.scan_mu)?;
    let epochs = if args.init.is_some() {
        config.finetune_epochs
    } else {
        config.pretrain_epochs
    };
    refuse_overwrite(&args.out, c.resume)?;
    let mut run = DrapeRun::load(&args.data, &config).with_context(|| format!("loading {}", args.data.display()))?;
    if let Some(n) = args.train_examples {
        anyhow::ensure!(
            n > 0 && n <= run.train.len(),
            "--train-examples {n}: {} has {} training examples",
            args.data.display(),
            run.train.len()
        );
        run.keep_training_prefix(n)?;
    }
    anyhow::ensure!(
        !run.train.is_empty() && !run.validation.is_empty(),
        "{} needs training and validation examples (it has {} and {})",
        args.data.display(),
        run.train.len(),
        run.validation.len()
    );
    let name = args
        .out
        .file_name()
        .map_or("model".into(), |n| n.to_string_lossy().into_owned());
    eprintln!(
        "drape/{name}: {layer}, {} training and {} validation examples on {} vertices, {epochs} epochs",
        run.train.len(),
        run.validation.len(),
        run.num_vertices()
    );
    let plan = Plan {
        name: &name,
        layer,
        init: args.init.as_deref(),
        epochs,
        retrain_on_mismatch: false,
    };
    let mut progress = TrainProgress::new(c.quiet, &format!("drape/{name}"))?;
    let fitted = run.fit(&args.out, &plan, &config, &mut progress)?;
    drop(progress);
    let summary = run.summarize(&args.out, &fitted, &config, &args.scan_mu)?;
    for line in summary.lines(&name) {
        eprintln!("{line}");
    }
    eprintln!("model → {}", args.out.display());
    Ok(())
}

fn embed(args: EmbedArgs) -> anyhow::Result<()> {
    use weft_nn::embed::{EmbedData, train_model};
    let c = &args.common;
    let config = embed_config(
        c.config.as_deref(),
        &c.overrides(),
        args.no_pb,
        c.autograd,
        &args.stages,
    )?;
    refuse_overwrite(&args.out, c.resume)?;
    let dataset =
        weft_data::ClothDataset::load(&args.data).with_context(|| format!("loading {}", args.data.display()))?;
    let name = dataset.name.clone();
    let data = EmbedData::new(dataset)?;
    eprintln!(
        "{name}: {} training and {} validation windows, {} vertices; L_phys scale {:?} {:.4e} m²/J (inertial \
         Δt²/m̄ {:.4e}, curvature 1/mean diag H {:.4e})",
        data.train_windows.len(),
        data.validation_windows.len(),
        data.num_vertices(),
        config.phys_scale,
        data.phys_scale(config.phys_scale),
        data.inertial_scale,
        data.curvature_scale
    );
    let mut progress = TrainProgress::new(c.quiet, &format!("embed/{name}"))?;
    let (_, states) = train_model(&args.out, &data, &config, &args.stages, &mut progress)?;
    drop(progress);
    for (stage, s) in states {
        eprintln!(
            "{name}: stage {stage}: kept epoch {} of {}, validation loss {:.4e}",
            s.best_epoch, s.epochs_done, s.best_validation
        );
    }
    eprintln!("model → {}", args.out.display());
    Ok(())
}

fn altconv(args: AltconvArgs) -> anyhow::Result<()> {
    use weft_nn::altconv::{Variant, train_model};
    let c = &args.common;
    let variant = Variant::from_name(&args.model)?;
    let mut config = altconv_config(c.config.as_deref(), &c.overrides(), variant, c.autograd)?;
    refuse_overwrite(&args.out, c.resume)?;
    let dataset =
        weft_data::LimbDataset::load(&args.data).with_context(|| format!("loading {}", args.data.display()))?;
    if !sets_field(c.config.as_deref(), "steps")? {
        if let Some(fit) = fit_altconv_steps(&mut config, &dataset) {
            eprintln!("{fit}");
        }
        config.validate()?;
    }
    eprintln!(
        "altconv/{}: {} training and {} validation sequences of {} steps, {} vertices",
        variant.name(),
        dataset.split("train").count(),
        dataset.split("validation").count(),
        config.steps,
        dataset.rest.num_vertices(),
    );
    let mut progress = TrainProgress::new(c.quiet, &format!("altconv/{}", variant.name()))?;
    let trained = train_model(&args.out, &dataset, &config, &mut progress)?;
    drop(progress);
    eprintln!(
        "altconv/{}: kept epoch {} of {}, validation {:.3} mm",
        variant.name(),
        trained.state.best_epoch,
        trained.state.epochs_done,
        1e3 * trained.state.best_validation
    );
    if let Some(summary) = weft_nn::altconv::validation_rollout(&args.out, &dataset, &trained)? {
        for (name, mm) in &summary.errors_mm {
            eprintln!(
                "altconv/{}: {name} roll-out error over steps 1-{} of the validation sequences: {mm:.3} mm",
                variant.name(),
                summary.steps
            );
        }
    }
    eprintln!("model → {}", args.out.display());
    Ok(())
}

fn nnwarp(args: NnwarpArgs) -> anyhow::Result<()> {
    use weft_nn::nnwarp::train_model;
    let c = &args.common;
    let material = args.material.as_str();
    let config = nnwarp_config(c.config.as_deref(), &c.overrides(), material)?;
    refuse_overwrite(&args.out, c.resume)?;
    let dataset = weft_data::WarpDataset::load(&args.data, material)
        .with_context(|| format!("loading {}", args.data.display()))?;
    let mut progress = TrainProgress::new(c.quiet, &format!("nnwarp/{material}"))?;
    let (state, n_train, n_val) = train_model(&args.out, &dataset, &config, &mut progress)?;
    drop(progress);
    eprintln!(
        "nnwarp/{material}: {n_train} training and {n_val} validation pairs; kept epoch {} of {}, validation {:.4e}",
        state.best_epoch, state.epochs_done, state.best_validation
    );
    eprintln!("model → {}", args.out.display());
    Ok(())
}
