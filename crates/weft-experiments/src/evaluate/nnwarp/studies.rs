//! The nnwarp experiment's studies: each material's network trained on growing prefixes of
//! the training sequences with every seed (the data-size study), the seed kept for the
//! figures chosen on validation, and the study's table and learning curve.

use std::path::{Path, PathBuf};

use super::WarpMaterial;
use crate::error::Context;
use crate::evaluate::context::EvalContext;
use crate::evaluate::study::Study;
use crate::records::{ExperimentOutput, LinePlot, Series};
use weft_nn::nnwarp::WarpTrainingSettings;

/// Training sequences of the data-size study (NNWarp trains on 520): sizes at or beyond
/// the dataset's training count are dropped and that count itself is always the last.
const DATA_SIZES: [usize; 4] = [64, 128, 256, 520];

/// One network of the data-size study.
pub(super) struct StudyRun {
    sequences: usize,
    seed: u64,
    /// The kept weights' correction error on the validation pairs
    /// ([`weft_nn::nnwarp::correction_rms`], unit-sphere units).
    validation_rms: f64,
    /// The epoch whose weights were kept.
    best_epoch: usize,
}

/// One material's networks: every (training sequences, seed) run's best validation score,
/// the seeds' final models (the largest size) and the one of them the validation split
/// selects.
pub(super) struct MaterialStudy {
    pub material: WarpMaterial,
    pub runs: Vec<StudyRun>,
    pub finals: Vec<PathBuf>,
    pub selected: PathBuf,
}

/// Trains material `m` on growing prefixes of the training sequences, each with every
/// seed, into `models/<material>/n<k>-seed<s>/` (resumed); selection reads the validation
/// split only.
pub(super) fn data_size_study(
    ctx: &EvalContext,
    root: &Path,
    data: &Path,
    m: WarpMaterial,
    config: &WarpTrainingSettings,
    seeds: &[u64],
) -> crate::Result<MaterialStudy> {
    let full = weft_data::WarpDataset::load(data, m.key())?;
    let available = full.training_count();
    let (val_x, val_y) = weft_nn::nnwarp::collect_pairs(&full, "validation")?;
    let mut sizes: Vec<usize> = DATA_SIZES.iter().copied().filter(|&k| k < available).collect();
    sizes.push(available);
    let mut runs = Vec::new();
    let mut finals = Vec::new();
    for &k in &sizes {
        let subset = full.with_training_prefix(k);
        for &seed in seeds {
            let dir = root.join("models").join(m.key()).join(format!("n{k}-seed{seed}"));
            let config = WarpTrainingSettings { seed, ..config.clone() };
            let label = format!("nnwarp/{}/n{k}-seed{seed}", m.key());
            let mut progress = crate::progress::TrainProgress::new(ctx.quiet, &label)?;
            let (state, _, _) = weft_nn::nnwarp::train_model(&dir, &subset, &config, &mut progress)
                .with_context(|| format!("training {label}"))?;
            let (_, mlp) = weft_nn::nnwarp::load_model(&dir)?;
            runs.push(StudyRun {
                sequences: k,
                seed,
                validation_rms: weft_nn::nnwarp::correction_rms(&mlp, &val_x, &val_y)?,
                best_epoch: state.best_epoch,
            });
            if k == available {
                finals.push(dir);
            }
        }
    }
    // The seeds' final models, chosen on their validation scores alone.
    let finals_scored: Vec<(PathBuf, f64)> = finals
        .into_iter()
        .zip(runs.iter().filter(|r| r.sequences == available))
        .map(|(dir, r)| (dir, r.validation_rms))
        .collect();
    let (finals_scored, best) = Study::from_trials(finals_scored, |&rms| rms)?.into_parts();
    let finals: Vec<PathBuf> = finals_scored.into_iter().map(|(dir, _)| dir).collect();
    Ok(MaterialStudy {
        material: m,
        runs,
        selected: finals[best].clone(),
        finals,
    })
}

/// The data-size study's learning curve (validation only) and table.
pub(super) fn study_report(out: &mut ExperimentOutput, studies: &[MaterialStudy], seeds: &[u64]) {
    let mut rows = Vec::new();
    let mut series = Vec::new();
    for study in studies {
        let mut sizes: Vec<usize> = study.runs.iter().map(|r| r.sequences).collect();
        sizes.dedup();
        let mut x = Vec::new();
        let mut y = Vec::new();
        for &k in &sizes {
            let at: Vec<&StudyRun> = study.runs.iter().filter(|r| r.sequences == k).collect();
            let (mean, sd) = crate::records::mean_sd(at.iter().map(|r| r.validation_rms));
            x.push(k as f64);
            y.push(mean);
            rows.push(vec![
                study.material.key().to_string(),
                k.to_string(),
                format!("{mean:.4e} ± {sd:.1e}"),
                at.iter()
                    .map(|r| format!("{} (seed {})", r.best_epoch, r.seed))
                    .collect::<Vec<_>>()
                    .join(", "),
            ]);
        }
        series.push(Series {
            label: study.material.key().to_string(),
            x,
            y,
        });
        let selected = study
            .selected
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned());
        out.notes.push(format!(
            "nnwarp/{}: selected on validation for the figures: `{selected}`",
            study.material.key()
        ));
    }
    out.tables.push(crate::paper::Table {
        title: "NNWarp — validation error against training data (data-size study)".into(),
        caption: format!(
            "Root-mean-square error of the runtime correction on every validation pair (unit-sphere units, mean ± sd \
             over {} seed(s); one scale for every run, unlike the trainer's standardised score) of each \
             material's network trained on the first k training sequences of the `nnwarp` dataset, and the epoch \
             each seed kept. The validation split only: the test shapes are scored once, with the largest k.",
            seeds.len()
        ),
        header: ["material", "training sequences", "validation RMS", "kept epochs"]
            .map(String::from)
            .to_vec(),
        rows,
    });
    out.lines.push(LinePlot {
        name: "data-size".into(),
        title: "NNWarp: validation error against training sequences".into(),
        x_label: "training sequences".into(),
        y_label: "validation correction RMS (unit-sphere units, mean over seeds)".into(),
        log_y: true,
        series,
    });
}
