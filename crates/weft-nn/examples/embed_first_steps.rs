//! The embedding's first optimizer steps, with and without the learning-rate warm-up:
//! stage 1 (the autoencoder) from each seed's initial weights, one Adam step per batch of
//! shuffled training windows, printing at chosen steps the batch loss and the mean |code|
//! `E(x)` over 32 fixed training windows, and at the end the fraction of decoder outputs
//! beyond ±0.96 (a saturated `tanh`). It is the measurement behind
//! `weft_nn::embed_training::WARMUP_STEPS` (docs/EMBEDDING.md, "Adam's first steps").
//! `DATA_DIR` is an `embed` dataset (`cargo xtask dataset`, or an evaluation's
//! `embed/data/<scene>`); `--config` a training configuration (default: the library's,
//! whose warm-up `--warmup` overrides).
//!
//! ```sh
//! cargo run --release -p weft-nn --example embed_first_steps -- \
//!     DATA_DIR [--config FILE] [--seeds 0 1 2] [--warmup 0 50] [--steps 500]
//! ```

use std::path::PathBuf;

use weft_nn::Device;
use weft_nn::adam::Adam;
use weft_nn::embed_training::{EmbedData, EmbedModel, EmbedTrainingConfig, FrameRef};
use weft_nn::trainer::{Trainer, shuffled};

const USAGE: &str = "usage: embed_first_steps DATA_DIR [--config FILE] [--seeds 0 1 2] [--warmup 0 50] [--steps 500]";

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
    let steps = *parse("--steps", "500")?.first().unwrap_or(&500);
    let base: EmbedTrainingConfig = match values(&args, "--config").as_deref() {
        Some([file]) => serde_json::from_str(&std::fs::read_to_string(file)?)?,
        Some(_) => return Err(format!("--config needs one file; {USAGE}").into()),
        None => EmbedTrainingConfig::default(),
    };
    let device = Device::Cpu;
    let data = EmbedData::new(weft_data::ClothDataset::load(&data_dir)?)?;
    let windows = &data.train_windows;
    let probe: Vec<FrameRef> = windows
        .iter()
        .step_by((windows.len() / 32).max(1))
        .take(32)
        .copied()
        .collect();
    let probe_features = data.feature_batch(&probe, &device)?;
    let report_at = [0, 1, 2, 5, 10, 25, 50, 100, 200, 300, 400];
    println!(
        "{} training windows, batch {}; columns: step: batch loss, mean |code|",
        windows.len(),
        base.batch
    );
    for &seed in &seeds {
        for &warmup in &warmups {
            let mut config = base.clone();
            config.seed = seed as u64;
            config.schedule.warmup_steps = warmup;
            let model = EmbedModel::new(config.clone(), &data)?;
            let group = model.stage_groups(1).remove(0);
            let mut adam = Adam::new(group.params, group.adam)?;
            // The trainer's own warm-up factor and shuffle, one epoch's order after another.
            let trainer = Trainer::new("probe", config.trainer(1));
            let mut order: Vec<usize> = Vec::new();
            let mut line = format!("seed {seed}, warm-up {warmup:>3} batches:");
            for step in 0..steps {
                if order.len() < config.batch {
                    order = shuffled(windows.len(), seed as u64 ^ step as u64);
                }
                let batch: Vec<FrameRef> = order.drain(..config.batch).map(|i| windows[i]).collect();
                adam.settings.learning_rate = group.adam.learning_rate * trainer.step_factor(step);
                let (loss, _) = model.losses(&data, &batch, 1, config.weights.ephys)?;
                let value = loss.to_scalar::<f32>()?;
                adam.step(group.params, &loss.backward()?)?;
                if report_at.contains(&step) || step + 1 == steps {
                    let code = model.autoencoder.encode(&probe_features)?;
                    let size = code.abs()?.mean_all()?.to_scalar::<f32>()?;
                    line += &format!("  {step}: {value:.3e}, {size:.2}");
                }
            }
            let decoded = model.autoencoder.decode(&model.autoencoder.encode(&probe_features)?)?;
            let saturated = decoded.abs()?.ge(0.96)?.to_dtype(candle_core::DType::F32)?.mean_all()?;
            println!("{line}; saturated outputs {:.3}", saturated.to_scalar::<f32>()?);
        }
    }
    Ok(())
}
