//! One drape model trained on a dataset directory and summarised, as `cargo xtask train
//! drape` runs it: the dataset's splits as tensors, the layers, training through
//! [`fit`], and what the run reports of the kept model — its scores on the validation and
//! test splits with cold solves (as the evaluation scores it), the second half of
//! training, and optionally the validation loss at fixed μ — written to the model
//! directory as `scores.json` and `mu-scan.json` and returned for printing.
//!
//! What is not here: argument parsing and printing (xtask's), and the evaluation's
//! records and tables (weft-experiments').

use std::path::Path;
use std::time::Instant;

use weft_proj::RestShape;

use crate::drape::{DrapeModel, DrapeTensors, predict_each, sqrtmse_maxdist_mm};
use crate::drape::{DrapeTrainingSettings, Fitted, Layers, Plan, fit};
use crate::error::{Error, Result};
use crate::trainer::Observer;

/// Per-split scores of one model, over the examples its postprocess succeeded on.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Scores {
    pub sqrtmse: f64,
    /// The training loss's measure: the mean of the squared per-example SqrtMSE (mm²).
    pub loss_mm2: f64,
    pub maxdist: f64,
    pub compression: f64,
    pub stretching: f64,
    pub seconds_per_example: f64,
    /// Examples the postprocess failed on, and the first failure.
    pub failed: usize,
    pub first_error: Option<String>,
}

/// Scores `model` on `data` (Geng et al.'s SqrtMSE and MaxDist in mm, and the errors of
/// the compression and stretching energies under stretch stiffness `k`, in mJ); returns
/// the scores and, per scored example, its index in `data` and its prediction.
pub fn score(
    model: &DrapeModel,
    data: &DrapeTensors,
    rest: &RestShape,
    k: f64,
    batch: usize,
) -> Result<(Scores, Vec<(usize, Vec<f64>)>)> {
    let start = Instant::now();
    let pred = predict_each(model, data, batch)?;
    let seconds_per_example = start.elapsed().as_secs_f64() / pred.len().max(1) as f64;
    let truth = data.truths()?;
    let mut s = Scores {
        sqrtmse: 0.0,
        loss_mm2: 0.0,
        maxdist: 0.0,
        compression: 0.0,
        stretching: 0.0,
        seconds_per_example,
        failed: 0,
        first_error: None,
    };
    let mut kept = Vec::with_capacity(pred.len());
    for (i, (p, t)) in pred.into_iter().zip(&truth).enumerate() {
        let p = match p {
            Ok(p) => p,
            Err(e) => {
                s.failed += 1;
                s.first_error.get_or_insert(e);
                continue;
            }
        };
        let (e, m) = sqrtmse_maxdist_mm(&p, t)?;
        s.sqrtmse += e;
        s.loss_mm2 += e * e;
        s.maxdist += m;
        let (a, b) = (
            weft_proj::strain_summary(rest, &p, k)?,
            weft_proj::strain_summary(rest, t, k)?,
        );
        s.compression += 1e3 * (a.compression_energy - b.compression_energy).abs();
        s.stretching += 1e3 * (a.stretching_energy - b.stretching_energy).abs();
        kept.push((i, p));
    }
    if kept.is_empty() {
        return Err(Error::PostprocessFailed {
            first: s.first_error.clone().unwrap_or_default(),
        });
    }
    let n = kept.len() as f64;
    s.sqrtmse /= n;
    s.loss_mm2 /= n;
    s.maxdist /= n;
    s.compression /= n;
    s.stretching /= n;
    Ok((s, kept))
}

/// A drape dataset read for training: its splits as tensors and the layers on its sleeve.
#[derive(Debug)]
pub struct DrapeRun {
    pub dataset: weft_data::DrapeDataset,
    pub layers: Layers,
    pub train: DrapeTensors,
    pub validation: DrapeTensors,
    pub test: DrapeTensors,
}

/// Where the second half of training settled (epochs `first..=last`).
#[derive(Debug, Clone, PartialEq)]
pub struct SecondHalf {
    pub first: usize,
    pub last: usize,
    /// The validation SqrtMSE's mean and population sd over those epochs (mm).
    pub validation_mean: f64,
    pub validation_sd: f64,
    /// The median over those epochs of |mean| / sd of μ's per-batch gradient (learned μ).
    pub mu_gradient_signal: Option<f64>,
}

/// What a drape run reports of the model it kept.
#[derive(Debug, Clone)]
pub struct DrapeSummary {
    /// Training batches skipped because the layer failed on them, and the first failure.
    pub skipped: (usize, Option<String>),
    pub kept_epoch: usize,
    /// The kept model's scores on the validation and test splits (those not empty).
    pub scores: Vec<(&'static str, Scores)>,
    /// Only when training ran more than one epoch in its second half.
    pub second_half: Option<SecondHalf>,
    /// The kept network's validation scores with the quasistatic layer at each fixed μ.
    pub mu_scan: Vec<(f64, Scores)>,
}

impl DrapeRun {
    /// Reads the drape dataset in `data` and builds its layers under `config`.
    pub fn load(data: &Path, config: &DrapeTrainingSettings) -> Result<Self> {
        let dataset = weft_data::DrapeDataset::load(data)?;
        let device = candle_core::Device::Cpu;
        let split = |name: &str| DrapeTensors::of_split(&dataset, name, &device);
        let (train, validation, test) = (split("train")?, split("validation")?, split("test")?);
        let layers = Layers::new(&dataset.sleeve, config)?;
        Ok(Self {
            dataset,
            layers,
            train,
            validation,
            test,
        })
    }

    /// Keeps the first `n` training examples only (a data-size study; validation and test
    /// stay whole).
    pub fn keep_training_prefix(&mut self, n: usize) -> Result<()> {
        self.train = self.train.select(&(0..n).collect::<Vec<_>>())?;
        Ok(())
    }

    /// The sleeve's vertex count.
    pub fn num_vertices(&self) -> usize {
        self.dataset.sleeve.num_vertices()
    }

    /// Trains (or continues) the model of `plan` into `out` through [`fit`].
    pub fn fit(
        &self,
        out: &Path,
        plan: &Plan<'_>,
        config: &DrapeTrainingSettings,
        observer: &mut dyn Observer,
    ) -> Result<Fitted> {
        fit(
            out,
            plan,
            config,
            &self.layers,
            &self.train,
            &self.validation,
            self.num_vertices(),
            observer,
        )
    }

    /// Scores the kept model of `fitted` and writes `scores.json` into `out` (and, with
    /// `scan_mu`, `mu-scan.json`: the loss of the kept network as μ alone varies; the μ
    /// study of docs/DRAPE.md). Validation and test are scored with cold solves, as the
    /// evaluation scores them.
    pub fn summarize(
        &self,
        out: &Path,
        fitted: &Fitted,
        config: &DrapeTrainingSettings,
        scan_mu: &[f64],
    ) -> Result<DrapeSummary> {
        let p = &fitted.state;
        let rest = RestShape::new(&self.dataset.sleeve)?;
        let k = config.quasistatic.stretch_stiffness;
        let mut scores = Vec::new();
        for (split, data) in [("validation", &self.validation), ("test", &self.test)] {
            if !data.is_empty() {
                scores.push((split, score(&fitted.model, data, &rest, k, config.batch)?.0));
            }
        }
        let mu = fitted
            .mu
            .as_ref()
            .map(|m| m.iter().sum::<f64>() / m.len().max(1) as f64);
        // Where training settles, over its second half: how much the validation error
        // scatters from epoch to epoch, where μ ends and how strong μ's gradient is against
        // its noise (the median over epochs of |mean| / sd of the per-batch gradient).
        let late = &p.history[p.history.len() / 2..];
        let n = late.len().max(1) as f64;
        let val_mean = late.iter().map(|h| h.validation).sum::<f64>() / n;
        let val_sd = (late.iter().map(|h| (h.validation - val_mean).powi(2)).sum::<f64>() / n).sqrt();
        let mut signal: Vec<f64> = late
            .iter()
            .filter_map(|h| Some((*h.extra.get("mu_gradient_mean")?, *h.extra.get("mu_gradient_sd")?)))
            .filter(|(_, sd)| *sd > 0.0)
            .map(|(mean, sd)| mean.abs() / sd)
            .collect();
        signal.sort_by(f64::total_cmp);
        let first = p.history.len() / 2 + 1;
        let second_half = serde_json::json!({
            "epochs": [first, p.history.len()],
            "validation_sqrtmse_mm_mean": val_mean,
            "validation_sqrtmse_mm_sd": val_sd,
            "last_mu": late.last().and_then(|h| h.extra.get("mu")),
            "mu_gradient_mean_over_sd_median": signal.get(signal.len() / 2),
        });
        let json_scores: serde_json::Map<String, serde_json::Value> = scores
            .iter()
            .map(|(split, s)| {
                let value = serde_json::json!({
                    "sqrtmse-mm": s.sqrtmse,
                    "maxdist-mm": s.maxdist,
                    "compression-energy-error": s.compression,
                    "stretching-energy-error": s.stretching,
                    "failed": s.failed,
                });
                (split.to_string(), value)
            })
            .collect();
        write_json(
            &out.join("scores.json"),
            &serde_json::json!({
                "kept_epoch": p.best_epoch,
                "epochs": p.epochs_done,
                "kept_mu_mean": mu,
                "second_half": second_half,
                "scores": json_scores,
            }),
        )?;
        let mut mu_scan = Vec::with_capacity(scan_mu.len());
        for &m in scan_mu {
            // The same cold solves as the scores.
            let model = self.layers.at_fixed_mu(&fitted.model.net, m);
            mu_scan.push((m, score(&model, &self.validation, &rest, k, config.batch)?.0));
        }
        if !scan_mu.is_empty() {
            let scan: Vec<_> = mu_scan
                .iter()
                .map(|(m, s)| {
                    serde_json::json!({
                        "mu": m,
                        "validation_sqrtmse_mm": s.sqrtmse,
                        "validation_loss_mm2": s.loss_mm2,
                        "failed": s.failed,
                    })
                })
                .collect();
            write_json(
                &out.join("mu-scan.json"),
                &serde_json::json!({ "kept_epoch": p.best_epoch, "kept_mu_mean": mu, "scan": scan }),
            )?;
        }
        Ok(DrapeSummary {
            skipped: {
                let (n, first) = p.skipped();
                (n, first.map(str::to_string))
            },
            kept_epoch: p.best_epoch,
            scores,
            second_half: (late.len() > 1).then(|| SecondHalf {
                first,
                last: p.history.len(),
                validation_mean: val_mean,
                validation_sd: val_sd,
                mu_gradient_signal: signal.get(signal.len() / 2).copied(),
            }),
            mu_scan,
        })
    }
}

/// Pretty JSON text written as the model directory's other files are: the text as
/// `serde_json::to_string_pretty` gives it, no trailing newline.
fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(value).expect("plain data");
    weft_data::files::write_text(path, &text)?;
    Ok(())
}

impl DrapeSummary {
    /// The lines `train drape` prints of its kept model, each starting `drape/{name}:` (the
    /// same figures are in `scores.json` and `mu-scan.json`).
    pub fn lines(&self, name: &str) -> Vec<String> {
        let mut lines = Vec::new();
        let (skipped, first) = &self.skipped;
        if *skipped > 0 {
            lines.push(format!(
                "drape/{name}: {skipped} training batches skipped because the layer failed on them; the first: {}",
                first.clone().unwrap_or_default()
            ));
        }
        for (split, s) in &self.scores {
            lines.push(format!(
                "drape/{name}: kept epoch {}: {split} SqrtMSE {:.4} mm, MaxDist {:.4} mm ({} examples failed)",
                self.kept_epoch, s.sqrtmse, s.maxdist, s.failed
            ));
        }
        if let Some(h) = &self.second_half {
            lines.push(format!(
                "drape/{name}: epochs {}-{}: validation SqrtMSE {:.4} ± {:.4} mm{}",
                h.first,
                h.last,
                h.validation_mean,
                h.validation_sd,
                h.mu_gradient_signal
                    .map_or(String::new(), |s| format!(", μ gradient median |mean|/sd {s:.3}"))
            ));
        }
        for (m, s) in &self.mu_scan {
            lines.push(format!(
                "drape/{name}: μ = {m}: validation SqrtMSE {:.4} mm, loss {:.5} mm² ({} examples failed)",
                s.sqrtmse, s.loss_mm2, s.failed
            ));
        }
        lines
    }
}

#[cfg(test)]
mod summary_tests {
    use super::*;

    #[test]
    fn summary_lines_name_the_model_and_leave_out_what_did_not_happen() {
        let scores = Scores {
            sqrtmse: 1.0,
            loss_mm2: 1.0,
            maxdist: 2.0,
            compression: 0.0,
            stretching: 0.0,
            seconds_per_example: 0.0,
            failed: 0,
            first_error: None,
        };
        let mut summary = DrapeSummary {
            skipped: (0, None),
            kept_epoch: 3,
            scores: vec![("validation", scores.clone())],
            second_half: None,
            mu_scan: Vec::new(),
        };
        let lines = summary.lines("m");
        assert_eq!(lines.len(), 1);
        assert!(lines[0].starts_with("drape/m: kept epoch 3: validation SqrtMSE 1.0000 mm"));
        summary.skipped = (2, Some("singular".into()));
        summary.mu_scan = vec![(0.1, scores)];
        let lines = summary.lines("m");
        assert_eq!(lines.len(), 3);
        assert!(lines[0].contains("2 training batches skipped") && lines[0].ends_with("singular"));
        assert!(lines[2].starts_with("drape/m: μ = 0.1: validation SqrtMSE"));
    }
}
