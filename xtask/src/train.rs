//! `cargo xtask train`: argument parsing for training weft-nn's models on pipeline
//! datasets. Every model trains through `weft_nn::trainer::Trainer` (one epoch loop,
//! validation-only model selection, a checkpoint each epoch, bit-identical resume); the
//! jobs that read a dataset, write a model directory and say what they did are
//! `weft_nn::train_job`'s. A model directory holds the configuration, what was fitted on the training
//! split (normalisation, scaling, standardisation) and the trainer's run: `training.json`,
//! `train.log`, `best/` and `last/` checkpoints.

use std::path::PathBuf;

use clap::{Args, Subcommand};

use weft_nn::train_job::{
    AltconvJob, DrapeJob, DrapeJobParams, EmbedJob, InertialCorrectionMlpJob, NnwarpJob, TrainJob, TrainParams,
};
use weft_nn::train_setup::{DrapeLayerKind, Overrides};

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
    /// A one-step surrogate for guarded roll-outs (docs/GUARD.md): the inertial predictor
    /// plus a ridge-regressed correction, fitted in closed form on a cloth dataset's training
    /// frames, the ridge weight chosen on its validation frames. Run it with
    /// `cargo xtask simulate SCENE --surrogate OUT --tolerance MM`.
    InertialCorrection(InertialCorrectionArgs),
    /// The nonlinear one-step surrogate (docs/GUARD.md): an MLP on the inertial
    /// correction's features adding to its codes, trained on a cloth dataset's training
    /// frames, the epoch kept by the validation frames' one-step M_rms. Run it with
    /// `cargo xtask simulate SCENE --surrogate OUT --tolerance MM`.
    #[command(after_help = weft_nn::config_help::INERTIAL_CORRECTION_MLP)]
    InertialCorrectionMlp(InertialCorrectionMlpArgs),
}

#[derive(Args)]
pub struct InertialCorrectionMlpArgs {
    /// A cloth dataset directory written by `cargo xtask dataset` (the scene the surrogate
    /// will run on).
    #[arg(long)]
    pub data: PathBuf,
    /// Where the model is written (`config.json`, `linear/`, the trainer's run `net/`).
    #[arg(long)]
    pub out: PathBuf,
    #[command(flatten)]
    pub common: TrainArgs,
}

#[derive(Args)]
pub struct InertialCorrectionArgs {
    /// A cloth dataset directory written by `cargo xtask dataset` (the scene the surrogate
    /// will run on).
    #[arg(long)]
    pub data: PathBuf,
    /// Where the model is written (`config.json`, `bases.safetensors`); must not hold one.
    #[arg(long)]
    pub out: PathBuf,
    /// Settings (JSON: `position_components`, `correction_components`, `ridge` — the
    /// candidate ridge weights relative to the mean squared feature); default 32, 32,
    /// [1e-8, 1e-6, 1e-4, 1e-2, 1].
    #[arg(long)]
    pub config: Option<PathBuf>,
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
    fn params<'a>(&'a self, data: &'a std::path::Path, out: &'a std::path::Path) -> TrainParams<'a> {
        TrainParams {
            data,
            out,
            config: self.config.as_deref(),
            overrides: Overrides {
                seed: self.seed,
                learning_rate: self.lr,
                epochs: self.epochs,
            },
            resume: self.resume,
            quiet: self.quiet,
            autograd: self.autograd,
        }
    }
}

pub fn run(cmd: TrainCommand) -> anyhow::Result<()> {
    match cmd {
        TrainCommand::Embed(a) => say(EmbedJob::new(a.common.params(&a.data, &a.out), a.no_pb, &a.stages)?),
        TrainCommand::Nnwarp(a) => say(NnwarpJob::new(a.common.params(&a.data, &a.out), &a.material)?),
        TrainCommand::Altconv(a) => say(AltconvJob::new(a.common.params(&a.data, &a.out), &a.model)?),
        TrainCommand::Drape(a) => {
            let drape = DrapeJobParams {
                layer: match a.layer {
                    DrapeLayer::None => DrapeLayerKind::None,
                    DrapeLayer::Socp => DrapeLayerKind::Socp,
                    DrapeLayer::Quasistatic => DrapeLayerKind::Quasistatic,
                },
                mu: a.mu,
                learn_mu: a.learn_mu.map(|l| l == LearnMu::PerVertex),
                init: a.init.as_deref(),
                scan_mu: &a.scan_mu,
                train_examples: a.train_examples,
            };
            say(DrapeJob::new(a.common.params(&a.data, &a.out), drape)?)
        }
        TrainCommand::InertialCorrectionMlp(a) => say(InertialCorrectionMlpJob::new(a.common.params(&a.data, &a.out))?),
        TrainCommand::InertialCorrection(a) => {
            let lines = weft_surrogate::fit_directory(&a.data, &a.out, a.config.as_deref())?;
            lines.iter().for_each(|line| eprintln!("{line}"));
            Ok(())
        }
    }
}

/// Says what `job` settled, trains it and says its report.
fn say(job: impl TrainJob) -> anyhow::Result<()> {
    job.notes().iter().for_each(|line| eprintln!("{line}"));
    job.start()?.iter().for_each(|line| eprintln!("{line}"));
    job.run()?.lines.iter().for_each(|line| eprintln!("{line}"));
    Ok(())
}
