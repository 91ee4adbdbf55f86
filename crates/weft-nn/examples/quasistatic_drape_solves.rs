//! The quasistatic layer on a drape dataset's training examples, cold: Newton iterations,
//! failures, wall time and SqrtMSE against the ground truth, for the predictions of one
//! or more trained drape networks (`cargo xtask train drape`, or the evaluation's models).
//! Built at two commits, it compares two versions of the layer's solver on the same
//! problems (docs/BENCHMARKS.md); `--out FILE` writes every equilibrium (f64, little
//! endian, in order) so that two runs' answers can be compared.
//!
//! ```sh
//! cargo run --release -p weft-nn --example quasistatic_drape_solves -- \
//!     DATA_DIR MU N MODEL_DIR [MODEL_DIR ...] [--out FILE]
//! ```

use std::path::PathBuf;
use std::time::Instant;

use weft_nn::drape::load_model;
use weft_nn::drape::{DrapeModel, DrapeTensors, Postprocess, predict_all};
use weft_proj::{QuasistaticLayer, ZeroLengthScaling};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    const USAGE: &str = "usage: quasistatic_drape_solves DATA_DIR MU N MODEL_DIR [MODEL_DIR ...] [--out FILE]";
    if args.iter().any(|a| a == "--help" || a == "-h") {
        println!("{USAGE}");
        return Ok(());
    }
    let out = match args.iter().position(|a| a == "--out") {
        Some(i) if i + 1 < args.len() => {
            let file = PathBuf::from(args.remove(i + 1));
            args.remove(i);
            Some(file)
        }
        Some(_) => return Err("--out needs a file".into()),
        None => None,
    };
    if args.len() < 4 {
        return Err(USAGE.into());
    }
    let data_dir = PathBuf::from(&args[0]);
    let mu: f64 = args[1].parse()?;
    let n: usize = args[2].parse()?;
    let dataset = weft_data::DrapeDataset::load(&data_dir)?;
    let device = candle_core::Device::Cpu;
    let train = DrapeTensors::of_split(&dataset, "train", &device)?;
    let n = n.min(train.len());
    let train = train.select(&(0..n).collect::<Vec<_>>())?;
    let truths = train.truths()?;
    let mut equilibria = Vec::new();
    for model_dir in &args[3..] {
        let (model, _, config) = load_model(&PathBuf::from(model_dir), &dataset.sleeve)?;
        let net = DrapeModel {
            net: model.net,
            post: Postprocess::None,
        };
        // The network's r̂ in batches of 16, as the evaluation scores.
        let predictions = predict_all(&net, &train, 16)?;
        let layer = QuasistaticLayer::new(&dataset.sleeve, config.quasistatic)?;
        let scaling = ZeroLengthScaling::Global(mu);
        let start = Instant::now();
        let (mut iterations, mut solved, mut sqrtmse) = (0, 0, 0.0);
        for (i, (pred, truth)) in predictions.iter().zip(&truths).enumerate() {
            match layer.forward(pred, &scaling) {
                Ok((solution, report)) => {
                    iterations += report.newton.iterations;
                    solved += 1;
                    sqrtmse += weft_nn::drape::sqrtmse_maxdist_mm(solution.positions(), truth)?.0;
                    equilibria.extend_from_slice(solution.positions());
                }
                Err(e) => println!("{model_dir}: example {i}: {e}"),
            }
        }
        println!(
            "{model_dir}: μ = {mu}, {n} examples: {solved} solved, {} failed, {:.1} Newton iterations per solve, \
             SqrtMSE {:.3} mm, {:.1} s",
            n - solved,
            iterations as f64 / solved.max(1) as f64,
            sqrtmse / solved.max(1) as f64,
            start.elapsed().as_secs_f64()
        );
    }
    if let Some(file) = out {
        std::fs::write(
            file,
            equilibria.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>(),
        )?;
    }
    Ok(())
}
