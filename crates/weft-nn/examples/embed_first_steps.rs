//! The embedding's first optimizer steps, with and without the learning-rate warm-up:
//! stage 1 (the autoencoder) from each seed's initial weights, trained by the trainer as
//! `cargo xtask train embed` trains it, printing at chosen batches the batch loss and the
//! mean |code| `E(x)` over 32 fixed training windows (the weights after that many steps),
//! and before the last batch the fraction of decoder outputs beyond ±0.96 on them (a
//! saturated `tanh`). It is the measurement behind `weft_nn::embed::WARMUP_STEPS`
//! (docs/EMBEDDING.md, "Adam's first steps"). `DATA_DIR` is an `embed` dataset (`cargo
//! xtask dataset`, or an evaluation's `embed/data/<scene>`); `--config` a training
//! configuration (default: the library's), whose warm-up `--warmup` overrides. Training
//! runs whole epochs, at least `--steps` batches.
//!
//! ```sh
//! cargo run --release -p weft-nn --example embed_first_steps -- \
//!     DATA_DIR [--config FILE] [--seeds 0 1 2] [--warmup 0 50] [--steps 500]
//! ```

use std::path::PathBuf;

use candle_core::{DType, Tensor};
use weft_nn::Device;
use weft_nn::embed::{EmbedData, EmbedModel, EmbedStage, EmbedTrainingSettings, FrameRef};
use weft_nn::trainer::{BatchAt, BatchLoss, Group, Silent, Trainable, Trainer};

const USAGE: &str = "usage: embed_first_steps DATA_DIR [--config FILE] [--seeds 0 1 2] [--warmup 0 50] [--steps 500]";

/// Batches at which the probe reports (and the last one).
const REPORT_AT: [usize; 6] = [1, 25, 50, 100, 200, 300];

/// Stage 1 as the trainer sees it, measuring the code before chosen batches.
struct Probe<'a> {
    stage: EmbedStage<'a>,
    model: &'a EmbedModel,
    probe: Tensor,
    batches_seen: usize,
    last: usize,
    line: String,
}

impl Probe<'_> {
    fn mean_code(&self) -> weft_nn::Result<f32> {
        Ok(self
            .model
            .autoencoder
            .encode(&self.probe)?
            .abs()?
            .mean_all()?
            .to_scalar::<f32>()?)
    }
}

impl Trainable for Probe<'_> {
    fn groups(&self) -> Vec<Group<'_>> {
        self.stage.groups()
    }
    fn num_examples(&self) -> usize {
        self.stage.num_examples()
    }
    fn batch_loss(&mut self, batch: &[usize], at: BatchAt) -> weft_nn::Result<BatchLoss> {
        let k = self.batches_seen;
        let loss = self.stage.batch_loss(batch, at)?;
        if REPORT_AT.contains(&k) || k == self.last {
            if let BatchLoss::Loss { loss, .. } = &loss {
                let value = loss.to_dtype(DType::F64)?.to_scalar::<f64>()?;
                self.line += &format!("  {k}: {value:.3e}, {:.2}", self.mean_code()?);
            }
        }
        if k == self.last {
            let decoded = self
                .model
                .autoencoder
                .decode(&self.model.autoencoder.encode(&self.probe)?)?;
            let saturated = decoded.abs()?.ge(0.96)?.to_dtype(DType::F32)?.mean_all()?;
            self.line += &format!("; saturated outputs {:.3}", saturated.to_scalar::<f32>()?);
        }
        self.batches_seen += 1;
        Ok(loss)
    }
    fn validation_score(&mut self) -> weft_nn::Result<f64> {
        self.stage.validation_score()
    }
    fn shuffle_seed(&self, seed: u64, epoch: usize) -> u64 {
        self.stage.shuffle_seed(seed, epoch)
    }
}

/// The values after `flag` up to the next flag.
fn values(args: &[String], flag: &str) -> Option<Vec<String>> {
    let i = args.iter().position(|a| a == flag)?;
    Some(
        args[i + 1..]
            .iter()
            .take_while(|a| !a.starts_with("--"))
            .cloned()
            .collect(),
    )
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.is_empty() || args.iter().any(|a| a == "--help" || a == "-h") {
        println!("{USAGE}");
        return Ok(());
    }
    let data_dir = PathBuf::from(&args[0]);
    let parse = |flag: &str, default: &str| -> Result<Vec<usize>, Box<dyn std::error::Error>> {
        let v = values(&args, flag).unwrap_or_else(|| default.split(' ').map(String::from).collect());
        if v.is_empty() {
            return Err(format!("{flag} needs at least one number; {USAGE}").into());
        }
        v.iter()
            .map(|s| s.parse::<usize>().map_err(|e| format!("{flag} {s:?}: {e}").into()))
            .collect()
    };
    let seeds = parse("--seeds", "0 1 2")?;
    let warmups = parse("--warmup", "0 50")?;
    let steps = parse("--steps", "500")?[0].max(1);
    let base: EmbedTrainingSettings = match values(&args, "--config").as_deref() {
        Some([file]) => serde_json::from_str(&std::fs::read_to_string(file)?)?,
        Some(_) => return Err(format!("--config needs one file; {USAGE}").into()),
        None => EmbedTrainingSettings::default(),
    };
    let data = EmbedData::new(weft_data::ClothDataset::load(&data_dir)?)?;
    let windows = &data.train_windows;
    let per_epoch = windows.len().div_ceil(base.batch.max(1));
    let epochs = steps.div_ceil(per_epoch);
    let probe: Vec<FrameRef> = windows
        .iter()
        .step_by((windows.len() / 32).max(1))
        .take(32)
        .copied()
        .collect();
    let probe = data.feature_batch(&probe, &Device::Cpu)?;
    println!(
        "{} training windows, {per_epoch} batches of {} an epoch, {epochs} epochs; columns: batch: its loss, \
         mean |code| before its step",
        windows.len(),
        base.batch
    );
    let dir = std::env::temp_dir().join(format!("weft-embed-first-steps-{}", std::process::id()));
    for &seed in &seeds {
        for &warmup in &warmups {
            let mut config = base.clone();
            config.seed = seed as u64;
            config.schedule.warmup_steps = warmup;
            config.epochs[0] = epochs;
            let model = EmbedModel::new(config.clone(), &data)?;
            let mut probe = Probe {
                stage: EmbedStage::new(&model, &data, 1),
                model: &model,
                probe: probe.clone(),
                batches_seen: 0,
                last: epochs * per_epoch - 1,
                line: format!("seed {seed}, warm-up {warmup:>3} batches:"),
            };
            let _ = std::fs::remove_dir_all(&dir);
            Trainer::new("probe", config.trainer(1)).run(&dir, &mut probe, &mut Silent)?;
            let _ = std::fs::remove_dir_all(&dir);
            println!("{}", probe.line);
        }
    }
    Ok(())
}
