//! What the embed experiment chooses on the validation windows, never the test split: the
//! first scene's studies (learning-rate schedule, stage-1 budget, stage 3's learning rate and
//! budget), each scene's λ_ephys from a grid around `no-pb`'s parity, and Table II's
//! λ_ephys models. Every choice goes through [`crate::evaluate::study::Study`]; the tables
//! that show them are [`super::tables`]'.

use std::path::{Path, PathBuf};

use weft_data::Size;
use weft_nn::embed::{EmbedData, EmbedTrainingSettings};
use weft_nn::trainer::{Decay, Schedule, TrainingState};

use super::scoring::{scored_model, scored_models, scored_runs, share_stages};
use super::tables::study_curves;
use super::{Job, ModelScores, Role, Scene, SceneResults, Studies, ValidationScores, method_config, with_seed};
use crate::error::Context;
use crate::evaluate::context::EvalContext;
use crate::evaluate::study::Study;
use crate::records::mean_sd;

/// Table II's loss weights: `λ_ephys` of the extra `sheet-ms` models beside `ours` (whose
/// λ_ephys is the configuration's, 0.5).
pub(super) const TABLE_II_EPHYS: [f64; 2] = [0.1, 1.0];

/// Stage-1 epochs allowed in the budget study: five times the configuration's 30. At
/// standard size an epoch holds 320 training windows (4 sequences of 170 frames, 8 windows
/// in every 17 frames) against about 1400 in the paper's one sequence of 2400 frames (10 in
/// every 17: Tan et al. had no validation frames), so 30 epochs are about 4.4 times fewer
/// steps here than there, and 150 about as many as 30 there (Tan et al. state no epoch
/// count; 30 is the configuration's). The study measures on validation what more epochs
/// buy, and the budget with the lower validation M_rms trains every model.
pub(super) const BUDGET_STUDY_EPOCHS: usize = 150;

/// The stage-1 epochs the first scene chooses between on validation: the configuration's and
/// [`BUDGET_STUDY_EPOCHS`] (quick runs keep the configuration's).
pub(super) fn budget_candidates(size: Size, config: &EmbedTrainingSettings) -> Vec<usize> {
    if size == Size::Quick {
        vec![config.epochs[0]]
    } else {
        vec![config.epochs[0], BUDGET_STUDY_EPOCHS]
    }
}

/// The learning-rate schedules tried, by name, beside the configuration's constant rate
/// (Tan et al.'s): halving the rate whenever the validation loss has not improved for two
/// epochs. The first scene's `no-pb` models (every seed) are trained under each, and the one
/// with the lowest mean validation M_rms is used by every model of the experiment. Quick
/// runs keep the configuration's.
pub(super) fn schedule_candidates(size: Size, config: &EmbedTrainingSettings) -> Vec<(&'static str, Schedule)> {
    let constant = config.schedule;
    if size == Size::Quick {
        return vec![("constant", constant)];
    }
    let plateau = Schedule {
        decay: Decay::ReduceOnPlateau {
            factor: 0.5,
            patience: 2,
        },
        ..constant
    };
    vec![("constant", constant), ("halve-on-plateau", plateau)]
}

/// Stage 3's learning rates the first scene chooses between on validation: the
/// configuration's (Tan et al.'s one rate for every stage) and a tenth of it. Stage 3
/// starts a fresh Adam on both trained networks; at the full rate its first epoch raised
/// the validation loss 4–8-fold and six of eight `sheet-ms` models kept their stage-2
/// weights (docs/EMBEDDING.md). Quick runs keep the configuration's.
pub(super) fn fine_tune_candidates(size: Size, config: &EmbedTrainingSettings) -> Vec<Option<f64>> {
    if size == Size::Quick {
        vec![config.fine_tune_learning_rate]
    } else {
        vec![
            config.fine_tune_learning_rate,
            Some(0.1 * config.stage_adam(3).learning_rate),
        ]
    }
}

/// Stage-3 epochs the first scene chooses between on validation, at the chosen stage-3
/// rate: Tan et al.'s 10 and three times as many. In the run before the warm-up every
/// `no-pb` seed's stage-3 validation loss still fell at its tenth epoch (docs/EMBEDDING.md).
/// The longer budget's models continue the shorter one's stage 3 (the trainer resumes it
/// exactly), so the study costs only the extra epochs.
pub(super) const STAGE_3_BUDGET_EPOCHS: usize = 30;

/// The stage-3 epochs the first scene chooses between: the configuration's and
/// [`STAGE_3_BUDGET_EPOCHS`] (quick runs keep the configuration's).
pub(super) fn stage_3_budget_candidates(size: Size, config: &EmbedTrainingSettings) -> Vec<usize> {
    if size == Size::Quick || config.epochs[2] >= STAGE_3_BUDGET_EPOCHS {
        vec![config.epochs[2]]
    } else {
        vec![config.epochs[2], STAGE_3_BUDGET_EPOCHS]
    }
}

/// The name of a stage-3 learning rate in the report and in directory names.
pub(super) fn fine_tune_name(config: &EmbedTrainingSettings, rate: Option<f64>) -> String {
    match rate {
        None => format!("{} (every stage's)", config.adam.learning_rate),
        Some(r) => format!("{r}"),
    }
}

/// The mean validation scores of a study candidate's models (one per seed).
pub(super) fn mean_validation(runs: &[(std::path::PathBuf, ModelScores)]) -> ValidationScores {
    ValidationScores {
        m_rms: mean_sd(runs.iter().map(|(_, s)| s.validation.m_rms)).0,
        m_phys: mean_sd(runs.iter().map(|(_, s)| s.validation.m_phys)).0,
    }
}

/// A study's row: the candidate, the seeds' mean validation M_rms, each seed's validation
/// M_rms and M_phys, and the epochs each seed's `stages` trained (the kept epoch in
/// brackets; stages joined by " / ", seeds by "; ").
pub(super) fn study_row(candidate: String, runs: &[(std::path::PathBuf, ModelScores)], stages: &[u8]) -> Vec<String> {
    let per_seed = |f: &dyn Fn(&ModelScores) -> String| runs.iter().map(|(_, s)| f(s)).collect::<Vec<_>>().join(", ");
    let trained: Vec<String> = runs
        .iter()
        .map(|(dir, _)| {
            stages
                .iter()
                .map(|&stage| {
                    TrainingState::read(&weft_nn::embed::stage_dir(dir, stage))
                        .map_or("—".into(), |t| format!("{} ({})", t.epochs_done, t.best_epoch))
                })
                .collect::<Vec<_>>()
                .join(" / ")
        })
        .collect();
    vec![
        candidate,
        format!("{:.3}", mean_validation(runs).m_rms),
        per_seed(&|s| format!("{:.3}", s.validation.m_rms)),
        per_seed(&|s| format!("{:.4e}", s.validation.m_phys)),
        trained.join("; "),
    ]
}

/// The λ_ephys grid of a scene, one chosen on the validation windows ([`choose_ephys`]). Tan et al. tuned λ_ephys per dataset among Table II's 0.1,
/// 0.5 and 1, under their own scale of `L_phys`. Weft's curvature scale makes the term's
/// *mean* curvature that of `L_vert`, but a trained autoencoder's errors lie in soft
/// directions, where `L_ephys` is far weaker: the weight at which it pulls a frame as
/// hard as `L_vert` ([`ephys_parity`], measured on `no-pb`'s first seed, validation
/// windows only) was about 200 on `sheet-ms`, and the fixed grids tried before (0.1 to 50)
/// left the validation M_phys at or above `no-pb`'s (docs/EMBEDDING.md). Beyond the quick
/// size the grid is that weight, rounded to one significant digit, and a decade either
/// side; without it (a baseline with no residual) the configuration's weight. Quick runs
/// keep fixed weights: the configuration's, except on `sheet-ms`, where the grid is Table
/// II's weights (trained at every size anyway).
pub(super) fn ephys_grid(size: Size, scene: &str, config: &EmbedTrainingSettings, parity: Option<f64>) -> Vec<f64> {
    let e = config.weights.ephys;
    let mut grid = match (size, scene, parity.and_then(one_significant_digit)) {
        (Size::Quick, "sheet-ms", _) => vec![TABLE_II_EPHYS[0], e, TABLE_II_EPHYS[1]],
        (Size::Quick, _, _) | (_, _, None) => vec![e],
        (_, _, Some((digit, exponent))) => (exponent - 1..=exponent + 1).map(|k| decimal(digit, k)).collect(),
    };
    grid.sort_by(f64::total_cmp);
    grid.dedup();
    grid
}

/// `x > 0` as `(d, k)` with `d · 10^k` its value rounded to one significant digit
/// (`d` in 1..=9, or 1 after rounding up to the next power of ten).
pub(super) fn one_significant_digit(x: f64) -> Option<(u32, i32)> {
    if !(x.is_finite() && x > 0.0) {
        return None;
    }
    let k = x.log10().floor() as i32;
    let d = (x / 10f64.powi(k)).round() as u32;
    Some(if d >= 10 { (1, k + 1) } else { (d.max(1), k) })
}

/// `d · 10^k` as the nearest f64 to the decimal (so 2 · 10¹ prints as `20`, not
/// `20.000000000000004`: the value names a model directory).
pub(super) fn decimal(d: u32, k: i32) -> f64 {
    format!("{d}e{k}").parse().unwrap_or(f64::NAN)
}

/// The λ_ephys at which `L_ephys` pulls a frame as hard as `L_vert` at a model with
/// validation scores `v`: on a frame `L_vert`'s gradient is `2δ` and `λ L_ephys`'s is
/// `λ s ∇_p L_phys` (`s` the physics scale, m/N), so the two are equal in norm at
/// `λ* = 2‖δ‖ / (s ‖∇_p L_phys‖)`, with `‖δ‖² = 3V M_rms²` and `‖∇_p L_phys‖² = M_phys`,
/// each the mean over the windows. Well below `λ*` the term barely moves a model that
/// `L_vert` and `L_recon` train. `None` without a residual or scale to divide by.
pub(super) fn ephys_parity(num_vertices: usize, v: ValidationScores, scale: f64) -> Option<f64> {
    let delta = (3.0 * num_vertices as f64).sqrt() * v.m_rms * 1e-3;
    let parity = 2.0 * delta / (scale * v.m_phys.sqrt());
    (parity.is_finite() && parity > 0.0).then_some(parity)
}

/// How far above `no-pb`'s validation M_rms a λ_ephys may take `ours` and still be
/// chosen for its M_phys: the claim's own tolerance (issue: "M_rms within 2 %").
pub(super) const EPHYS_RMS_TOLERANCE: f64 = 0.02;

/// The λ_ephys to keep from `(λ, validation scores)` candidates: the lowest M_phys among
/// those whose M_rms is within [`EPHYS_RMS_TOLERANCE`] of the baseline's, else the lowest
/// M_rms; `None` without candidates.
pub(super) fn choose_ephys(candidates: &[(f64, ValidationScores)], baseline: ValidationScores) -> Option<f64> {
    let limit = (1.0 + EPHYS_RMS_TOLERANCE) * baseline.m_rms;
    candidates
        .iter()
        .filter(|(_, v)| v.m_rms <= limit)
        .min_by(|a, b| a.1.m_phys.total_cmp(&b.1.m_phys))
        .or_else(|| candidates.iter().min_by(|a, b| a.1.m_rms.total_cmp(&b.1.m_rms)))
        .map(|(e, _)| *e)
}

/// Adds a study's runs to the first scene's study models, each directory once.
pub(super) fn add_to_study(study: &mut Vec<(PathBuf, ModelScores)>, runs: Vec<(PathBuf, ModelScores)>) {
    for run in runs {
        if !study.iter().any(|(d, _)| *d == run.0) {
            study.push(run);
        }
    }
}

/// One candidate of a stage-3 study on the first scene: `no-pb` on every seed, trained
/// (unless kept) and scored under `configs[k]`, seed k's configuration. With `copy` =
/// `None` the candidate is the configuration's own, and seed k's model is `sources[k]`;
/// with `Some((dir, through))` it is a copy of `sources[k]`'s stages 1..=`through` in
/// `dir/seed-{seed}` (made once) whose later stages train under the candidate.
pub(super) fn stage_3_candidate_runs(
    ctx: &EvalContext,
    data: &EmbedData,
    scene: &str,
    configs: &[EmbedTrainingSettings],
    sources: &[PathBuf],
    copy: Option<(&Path, u8)>,
) -> crate::Result<Vec<(PathBuf, ModelScores)>> {
    let mut jobs = Vec::new();
    for (k, (config, source)) in configs.iter().zip(sources).enumerate() {
        let dir = match copy {
            None => source.clone(),
            Some((copies, through)) => {
                let dir = copies.join(format!("seed-{}", config.seed));
                if !dir.join("config.json").exists() {
                    share_stages(source, &dir, through)?;
                }
                dir
            }
        };
        let role = Role {
            scene,
            method: "no-pb",
            first_seed: k == 0,
        };
        jobs.push(Job::new(config.clone(), dir, role));
    }
    scored_runs(ctx, data, &jobs)
}

/// A model directory and its scores: one seed of a candidate.
pub(super) type Run = (PathBuf, ModelScores);

/// The directory of a study model (in `study`) trained under `c`, else `otherwise`.
pub(super) fn study_dir_or(study: &[Run], c: &EmbedTrainingSettings, otherwise: PathBuf) -> PathBuf {
    study
        .iter()
        .find(|(_, s)| c.trains_like(&s.config))
        .map_or(otherwise, |(d, _)| d.clone())
}

/// The first scene's studies, each on the validation windows and each choice written into
/// `r.config` before the next study trains: the learning-rate schedule, the stage-1 budget,
/// stage 3's learning rate and stage 3's budget (a study with one candidate is skipped).
/// Returns every model they trained (`no-pb` models), for the scene's `no-pb` seeds to
/// reuse where one has the configuration a seed needs.
pub(super) fn run_studies(s: &Scene, studies: &Studies, r: &mut SceneResults) -> crate::Result<Vec<Run>> {
    let mut study = Vec::new();
    if studies.schedules.len() > 1 {
        schedule_study(s, &studies.schedules, r, &mut study)?;
    }
    if studies.budgets.len() > 1 {
        budget_study(s, &studies.budgets, r, &mut study)?;
    }
    if studies.fine_tune.len() > 1 {
        r.fine_tune_rows = stage_3_study(s, &STAGE_3_RATE, &studies.fine_tune, r, &mut study)?;
    }
    if studies.stage_3_budgets.len() > 1 {
        r.stage_3_budget_rows = stage_3_study(s, &STAGE_3_BUDGET, &studies.stage_3_budgets, r, &mut study)?;
    }
    Ok(study)
}

/// The learning-rate schedule, on the first scene's validation windows: `no-pb` under each
/// candidate, every seed (one seed's M_rms varies too much to choose on); the chosen
/// candidate's models are the scene's `no-pb`, and every other model of the experiment
/// trains under it.
fn schedule_study(
    s: &Scene,
    schedules: &[(&'static str, Schedule)],
    r: &mut SceneResults,
    study: &mut Vec<Run>,
) -> crate::Result<()> {
    // Every candidate's seeds at once: none depends on another.
    let study_root = s.models.join("schedule-study");
    let no_pb = method_config(&r.config, true);
    let jobs: Vec<Job> = schedules
        .iter()
        .flat_map(|(name, schedule)| {
            let (study_root, no_pb) = (&study_root, &no_pb);
            s.seeds.iter().enumerate().map(move |(k, &seed)| {
                let c = EmbedTrainingSettings {
                    schedule: *schedule,
                    ..with_seed(no_pb, seed)
                };
                let dir = study_root.join(name).join(format!("seed-{seed}"));
                Job::new(c, dir, s.role("no-pb", k == 0))
            })
        })
        .collect();
    let all = scored_runs(s.ctx, &s.data, &jobs)?;
    let trials = schedules
        .iter()
        .copied()
        .zip(all.chunks(s.seeds.len()).map(<[Run]>::to_vec))
        .collect();
    let schedules =
        Study::from_trials(trials, |runs| mean_validation(runs).m_rms).context("the learning-rate schedule study")?;
    r.schedule_rows = schedules.rows(|(name, _), runs| study_row((*name).to_string(), runs, &[1, 2, 3]));
    for (_, runs) in schedules.trials() {
        study.extend_from_slice(runs);
    }
    let (chosen, schedule) = *schedules.chosen();
    r.config.schedule = schedule;
    r.output.notes.push(format!(
        "embed: learning-rate schedule `{chosen}` chosen on `{}`'s validation windows (the schedule table)",
        s.name
    ));
    Ok(())
}

/// The stage-1 budget, on the same validation windows: `no-pb`'s first seed under the
/// chosen schedule with the configuration's epochs (a model of the schedule study) and with
/// [`BUDGET_STUDY_EPOCHS`] allowed; every model of the experiment trains with the choice.
fn budget_study(s: &Scene, budgets: &[usize], r: &mut SceneResults, study: &mut Vec<Run>) -> crate::Result<()> {
    let no_pb = with_seed(&method_config(&r.config, true), s.seeds[0]);
    let budgets = Study::sweep(
        budgets.iter().copied(),
        |&epochs| {
            let mut c = no_pb.clone();
            c.epochs[0] = epochs;
            let dir = study_dir_or(
                study,
                &c,
                s.models.join("budget-study").join(format!("stage-1-{epochs}")),
            );
            let scores = scored_model(s.ctx, &s.data, &c, &dir, s.role("no-pb", true))?;
            let row = budget_row(epochs, &dir, scores.validation);
            add_to_study(study, vec![(dir.clone(), scores.clone())]);
            Ok((dir, scores, row))
        },
        |(_, scores, _)| scores.validation.m_rms,
    )
    .context("the stage-1 budget study")?;
    r.budget_rows = budgets.rows(|_, (_, _, row)| row.clone());
    let chosen = *budgets.chosen();
    r.config.epochs[0] = chosen;
    r.output.notes.push(format!(
        "embed: {chosen} stage-1 epochs allowed, chosen on `{}`'s validation windows (the budget table)",
        s.name
    ));
    let curves: Vec<(String, PathBuf)> = budgets
        .trials()
        .iter()
        .map(|(epochs, (dir, _, _))| (format!("{epochs} epochs allowed"), dir.clone()))
        .collect();
    r.output
        .lines
        .push(study_curves(s.name, "budget-study", "budget", &curves, 1));
    Ok(())
}

/// The budget study's row of the model in `dir`: the budget, the epochs each stage trained
/// (and kept), its validation scores and its training seconds.
fn budget_row(epochs: usize, dir: &Path, validation: ValidationScores) -> Vec<String> {
    let states: Vec<Option<TrainingState>> = (1..=3u8)
        .map(|stage| TrainingState::read(&weft_nn::embed::stage_dir(dir, stage)).ok())
        .collect();
    let trained: Vec<String> = states
        .iter()
        .map(|t| {
            t.as_ref()
                .map_or("—".into(), |t| format!("{} (kept {})", t.epochs_done, t.best_epoch))
        })
        .collect();
    let seconds: f64 = states.iter().flatten().map(TrainingState::train_seconds).sum();
    vec![
        epochs.to_string(),
        trained.join(" / "),
        format!("{:.3}", validation.m_rms),
        format!("{:.4e}", validation.m_phys),
        format!("{seconds:.0}"),
    ]
}

/// What sets one of the two stage-3 studies apart: the value each candidate gives the
/// configuration, and how the study names it.
pub(super) struct Stage3Study<T> {
    /// The study's directory under the scene's models, and its plot's name.
    dir: &'static str,
    /// What the plot's lines differ in.
    what: &'static str,
    /// The source stages a candidate other than the configuration's copies (2: it trains
    /// its own stage 3; 3: it trains the source's stage 3 on).
    through: u8,
    get: fn(&EmbedTrainingSettings) -> T,
    set: fn(&mut EmbedTrainingSettings, T),
    /// A candidate's name in the table.
    name: fn(&EmbedTrainingSettings, T) -> String,
    /// A candidate's directory (under `dir`), from its name.
    candidate_dir: fn(&str) -> String,
    /// A candidate's line in the plot, from its name.
    curve: fn(&str) -> String,
    /// The note on the choice, from the chosen name and the scene.
    note: fn(&str, &str) -> String,
}

/// Stage 3's learning rate, on the same validation windows: `no-pb`, every seed, with
/// stage 3 trained under each candidate from the same stages 1 and 2 (copied from the
/// model under the configuration's rate, the first candidate); every model of the
/// experiment fine-tunes at the choice.
pub(super) const STAGE_3_RATE: Stage3Study<Option<f64>> = Stage3Study {
    dir: "stage-3-study",
    what: "learning rate",
    through: 2,
    get: |c| c.fine_tune_learning_rate,
    set: |c, rate| c.fine_tune_learning_rate = rate,
    name: fine_tune_name,
    candidate_dir: |name| format!("lr-{name}"),
    curve: |name| format!("stage-3 rate {name}"),
    note: |name, scene| {
        format!("embed: stage-3 learning rate {name} chosen on `{scene}`'s validation windows (the stage-3 table)")
    },
};

/// Stage 3's budget, on the same validation windows: `no-pb`, every seed, at the chosen
/// stage-3 rate, with each candidate's stage-3 epochs; a longer budget's model is a copy
/// of the shorter one's whose stage 3 trains on (exactly the run a fresh model makes).
pub(super) const STAGE_3_BUDGET: Stage3Study<usize> = Stage3Study {
    dir: "stage-3-budget-study",
    what: "stage-3 budget",
    through: 3,
    get: |c| c.epochs[2],
    set: |c, epochs| c.epochs[2] = epochs,
    name: |_, epochs| epochs.to_string(),
    candidate_dir: |name| format!("stage-3-{name}"),
    curve: |name| format!("{name} stage-3 epochs allowed"),
    note: |name, scene| {
        format!(
            "embed: {name} stage-3 epochs allowed, chosen on `{scene}`'s validation windows (the stage-3 budget table)"
        )
    },
};

/// One stage-3 study on the first scene ([`STAGE_3_RATE`], [`STAGE_3_BUDGET`]): `no-pb`,
/// every seed, under each candidate, each seed's stage 3 starting from the study model
/// that trains like the configuration (else the seed's `no-pb` model). Writes the choice
/// into `r.config`, its note and plot into `r.output`; returns the study's table rows.
fn stage_3_study<T: Copy + PartialEq>(
    s: &Scene,
    spec: &Stage3Study<T>,
    candidates: &[T],
    r: &mut SceneResults,
    study: &mut Vec<Run>,
) -> crate::Result<Vec<Vec<String>>> {
    let current = (spec.get)(&r.config);
    let no_pb = method_config(&r.config, true);
    let at = |value: T, seed: u64| {
        let mut c = with_seed(&no_pb, seed);
        (spec.set)(&mut c, value);
        c
    };
    let sources: Vec<PathBuf> = s
        .seeds
        .iter()
        .map(|&seed| {
            let c = at(current, seed);
            study_dir_or(study, &c, s.seed_dir("no-pb", c.seed))
        })
        .collect();
    let config = &r.config;
    let trials = Study::sweep(
        candidates.iter().copied(),
        |&value| {
            let name = (spec.name)(config, value);
            let configs: Vec<EmbedTrainingSettings> = s.seeds.iter().map(|&seed| at(value, seed)).collect();
            let copies = s.models.join(spec.dir).join((spec.candidate_dir)(&name));
            let copy = (value != current).then_some((copies.as_path(), spec.through));
            let runs = stage_3_candidate_runs(s.ctx, &s.data, s.name, &configs, &sources, copy)?;
            let row = study_row(name.clone(), &runs, &[3]);
            add_to_study(study, runs.clone());
            Ok((name, runs, row))
        },
        |(_, runs, _)| mean_validation(runs).m_rms,
    )
    .with_context(|| format!("the {} study", spec.dir))?;
    let rows = trials.rows(|_, (_, _, row)| row.clone());
    let curves: Vec<(String, PathBuf)> = trials
        .trials()
        .iter()
        .map(|(_, (name, runs, _))| ((spec.curve)(name), runs[0].0.clone()))
        .collect();
    let chosen_name = trials.chosen_outcome().0.clone();
    (spec.set)(&mut r.config, *trials.chosen());
    r.output.notes.push((spec.note)(&chosen_name, s.name));
    r.output
        .lines
        .push(study_curves(s.name, spec.dir, spec.what, &curves, 3));
    Ok(rows)
}

/// `ours`'s configuration at λ_ephys `ephys` with `seed`.
fn ours_config(config: &EmbedTrainingSettings, ephys: f64, seed: u64) -> EmbedTrainingSettings {
    let mut c = with_seed(&method_config(config, false), seed);
    c.weights.ephys = ephys;
    c
}

/// The method directory of `ours` at λ_ephys `ephys`.
fn ours_method(ephys: f64) -> String {
    format!("ours-ephys-{ephys}")
}

/// `no-pb`, every seed (on the first scene, a study's model where one has the seed's
/// configuration), and `ours`: the first seed at every λ_ephys of the scene's grid, the
/// weight chosen on the validation windows only ([`choose_ephys`] against `no-pb`'s first
/// seed), the other seeds at the chosen weight. As many `no-pb` seeds as train at once go
/// first; the rest train beside the grid, which needs only the first seed's scores.
/// Returns `(no-pb, ours)`, each seed's run, the first seed first.
pub(super) fn baseline_and_ours(s: &Scene, study: &[Run], r: &mut SceneResults) -> crate::Result<(Vec<Run>, Vec<Run>)> {
    let config = r.config.clone();
    let baseline_jobs: Vec<Job> = s
        .seeds
        .iter()
        .enumerate()
        .map(|(k, &seed)| {
            let c = with_seed(&method_config(&config, true), seed);
            let dir = study_dir_or(study, &c, s.seed_dir("no-pb", seed));
            Job::new(c, dir, s.role("no-pb", k == 0))
        })
        .collect();
    let (first_jobs, later_jobs) = baseline_jobs.split_at(s.ctx.workers(baseline_jobs.len()));
    let mut baseline_scores = scored_models(s.ctx, &s.data, first_jobs)?;
    let baseline_validation = baseline_scores[0].validation;
    let parity = ephys_parity(
        s.data.num_vertices(),
        baseline_validation,
        s.data.phys_scale(config.phys_scale),
    );
    let grid = ephys_grid(s.ctx.size, s.name, &config, parity);
    if let Some(parity) = parity.filter(|_| grid.len() > 1) {
        r.output.notes.push(format!(
            "embed/{}: `no-pb`'s first seed has λ_ephys parity {parity:.3} on the validation windows; \
             the λ_ephys grid is {grid:?}",
            s.name
        ));
    }
    let grid_jobs = grid.iter().map(|&ephys| {
        Job::new(
            ours_config(&config, ephys, s.seeds[0]),
            s.seed_dir(&ours_method(ephys), s.seeds[0]),
            s.role("ours", true),
        )
    });
    let jobs: Vec<Job> = later_jobs.iter().cloned().chain(grid_jobs).collect();
    let mut scored = scored_runs(s.ctx, &s.data, &jobs)?;
    let grid_runs = scored.split_off(later_jobs.len());
    baseline_scores.extend(scored.into_iter().map(|(_, scores)| scores));
    let baseline: Vec<Run> = baseline_jobs
        .iter()
        .map(|j| j.dir.clone())
        .zip(baseline_scores)
        .collect();
    let ephys = Study::choose_with(grid.iter().copied().zip(grid_runs).collect(), |trials| {
        let validation: Vec<(f64, ValidationScores)> = trials.iter().map(|(e, (_, s))| (*e, s.validation)).collect();
        let chosen = choose_ephys(&validation, baseline_validation)?;
        trials.iter().position(|(e, _)| *e == chosen)
    })
    .context("no λ_ephys candidate")?;
    let chosen = *ephys.chosen();
    let jobs: Vec<Job> = s.seeds[1..]
        .iter()
        .map(|&seed| {
            Job::new(
                ours_config(&config, chosen, seed),
                s.seed_dir(&ours_method(chosen), seed),
                s.role("ours", false),
            )
        })
        .collect();
    let mut ours = vec![ephys.chosen_outcome().clone()];
    ours.extend(scored_runs(s.ctx, &s.data, &jobs)?);
    if grid.len() > 1 {
        let row = ephys_row(s.name, parity, ephys.trials(), baseline_validation, chosen);
        r.ephys_row = Some((grid, row));
    }
    Ok((baseline, ours))
}

/// The λ_ephys table's row of a scene: its parity, each grid weight's validation scores,
/// `no-pb`'s and the choice.
fn ephys_row(
    scene: &str,
    parity: Option<f64>,
    grid: &[(f64, Run)],
    baseline: ValidationScores,
    chosen: f64,
) -> Vec<String> {
    let mut row = vec![format!("`{scene}`"), parity.map_or("—".into(), |p| format!("{p:.1}"))];
    row.extend(
        grid.iter()
            .map(|(e, (_, s))| format!("{e}: {:.3} / {:.4e}", s.validation.m_rms, s.validation.m_phys)),
    );
    row.push(format!("{:.3} / {:.4e}", baseline.m_rms, baseline.m_phys));
    row.push(format!("{chosen}"));
    row
}

/// Table II on `sheet-ms`: every seed at each of the paper's λ_ephys (the chosen weight's
/// are `ours`; the others' first seeds are the grid's models), their test scores as
/// columns.
pub(super) fn table_2_models(s: &Scene, r: &mut SceneResults) -> crate::Result<()> {
    let config = &r.config;
    let weights = [TABLE_II_EPHYS[0], config.weights.ephys, TABLE_II_EPHYS[1]];
    let jobs: Vec<Job> = weights
        .iter()
        .flat_map(|&ephys| s.seeds.iter().enumerate().map(move |(k, &seed)| (ephys, k, seed)))
        .map(|(ephys, k, seed)| {
            Job::new(
                ours_config(config, ephys, seed),
                s.seed_dir(&ours_method(ephys), seed),
                s.role("ours", k == 0),
            )
        })
        .collect();
    let scored = scored_models(s.ctx, &s.data, &jobs)?;
    for (ephys, runs) in weights.iter().zip(scored.chunks(s.seeds.len())) {
        r.table_2
            .push((format!("(1, 1, {ephys})"), runs.iter().map(|s| s.test).collect()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::scoring::{score, validation_scores};
    use super::*;
    use crate::evaluate::embed::tests::simulated_sheet;
    use crate::evaluate::embed::*;
    use weft_nn::embed::EmbedModel;

    /// λ_ephys is chosen from validation scores by the documented rule, and those scores
    /// read no test frame: poisoning every test frame changes the test scores and leaves
    /// the validation scores, hence the choice, bit for bit as they were.
    #[test]
    fn the_ephys_grid_spans_a_decade_either_side_of_parity_beyond_the_quick_size() {
        let config = training_config(Size::Standard);
        assert_eq!(config.weights.ephys, 0.5);
        for scene in ["sheet-ms", "ball-fem"] {
            assert_eq!(
                ephys_grid(Size::Standard, scene, &config, Some(205.8)),
                [20.0, 200.0, 2000.0]
            );
            assert_eq!(ephys_grid(Size::Standard, scene, &config, None), [0.5]);
        }
        // Rounding up across a power of ten, and below one: exact decimals, as named.
        assert_eq!(
            ephys_grid(Size::Paper, "ball-ms", &config, Some(9.7)),
            [1.0, 10.0, 100.0]
        );
        let small = ephys_grid(Size::Standard, "ball-ms", &config, Some(0.0316));
        assert_eq!(small, [0.003, 0.03, 0.3]);
        assert_eq!(format!("{}", small[0]), "0.003");
        assert_eq!(one_significant_digit(0.0), None);
        assert_eq!(one_significant_digit(f64::NAN), None);
        let quick = training_config(Size::Quick);
        assert_eq!(
            ephys_grid(Size::Quick, "sheet-ms", &quick, Some(200.0)),
            [0.1, 0.5, 1.0]
        );
        assert_eq!(ephys_grid(Size::Quick, "ball-fem", &quick, Some(200.0)), [0.5]);
    }

    /// Parity is where the two gradients are equal: at λ*, λ* s ‖∇L_phys‖ = 2‖δ‖ with the
    /// norms the scores imply; it scales as M_rms / √M_phys / s.
    #[test]
    fn ephys_parity_balances_the_two_gradients() {
        let v = ValidationScores {
            m_rms: 6.92,
            m_phys: 243.7,
        };
        let (n, s) = (4225, 2.0e-4);
        let parity = ephys_parity(n, v, s).unwrap();
        let delta = (3.0 * n as f64 * (v.m_rms * 1e-3).powi(2)).sqrt();
        assert!((parity * s * v.m_phys.sqrt() - 2.0 * delta).abs() < 1e-12 * delta);
        let doubled = ValidationScores {
            m_rms: 2.0 * v.m_rms,
            m_phys: 4.0 * v.m_phys,
        };
        assert!((ephys_parity(n, doubled, s).unwrap() - parity).abs() < 1e-12 * parity);
        assert_eq!(
            ephys_parity(
                n,
                ValidationScores {
                    m_rms: 1.0,
                    m_phys: 0.0
                },
                s
            ),
            None
        );
        assert_eq!(ephys_parity(n, v, 0.0), None);
    }

    #[test]
    fn the_ephys_choice_reads_the_validation_split_only() {
        let v = |m_rms, m_phys| ValidationScores { m_rms, m_phys };
        let base = v(10.0, 100.0);
        // 0.5 has the lowest M_phys but is 3 % off the baseline's M_rms; 1.0 is within.
        let within = [(0.1, v(10.1, 90.0)), (0.5, v(10.3, 50.0)), (1.0, v(9.0, 80.0))];
        assert_eq!(choose_ephys(&within, base), Some(1.0));
        // None within 2 %: the lowest M_rms.
        assert_eq!(
            choose_ephys(&[(0.1, v(11.0, 1.0)), (0.5, v(10.5, 95.0))], base),
            Some(0.5)
        );
        assert_eq!(choose_ephys(&[], base), None);

        let (clean, poisoned) = (
            EmbedData::new(simulated_sheet(20, false)).unwrap(),
            EmbedData::new(simulated_sheet(20, true)).unwrap(),
        );
        let config = training_config(Size::Quick);
        let mut choices = Vec::new();
        for data in [&clean, &poisoned] {
            // Two candidates that differ (their initial weights), scored untrained.
            let candidates: Vec<(f64, ValidationScores)> = [(0.1, 0), (1.0, 1)]
                .into_iter()
                .map(|(ephys, seed)| {
                    let model = EmbedModel::new(with_seed(&config, seed), data).unwrap();
                    (ephys, validation_scores(data, &model).unwrap())
                })
                .collect();
            assert_ne!(candidates[0].1, candidates[1].1);
            let baseline = candidates[0].1;
            choices.push((candidates.clone(), choose_ephys(&candidates, baseline)));
        }
        assert_eq!(choices[0], choices[1]);
        let model = EmbedModel::new(config, &clean).unwrap();
        let test = |data: &EmbedData| {
            let predicted = model.reconstruct(data, &data.test_frames, 16).unwrap();
            score(data, &predicted).unwrap().m_rms
        };
        let (a, b) = (test(&clean), test(&poisoned));
        assert!(
            (a - b).abs() > 1e-3 * a,
            "the poison reaches the test scores: {a} vs {b}"
        );
    }

    /// Beyond the quick size every stage stops once flat and two schedules compete; the
    /// choice is the lowest validation M_rms, and the candidates differ only in the decay.
    #[test]
    fn the_schedule_is_chosen_on_validation_m_rms_and_training_stops_once_flat() {
        let quick = training_config(Size::Quick);
        assert_eq!(schedule_candidates(Size::Quick, &quick).len(), 1);
        let standard = training_config(Size::Standard);
        assert_eq!(standard.epochs, [30, 30, 10]);
        assert_eq!(standard.schedule.early_stopping_patience, Some(EARLY_STOPPING_PATIENCE));
        let candidates = schedule_candidates(Size::Standard, &standard);
        assert_eq!(candidates[0].1, standard.schedule);
        assert!(matches!(candidates[1].1.decay, Decay::ReduceOnPlateau { .. }));
        assert_eq!(
            candidates[1].1.early_stopping_patience,
            standard.schedule.early_stopping_patience
        );
        // The studies' rule: [`Study::from_trials`] on the candidates' mean validation M_rms.
        fn lowest_m_rms<T: Copy>(candidates: &[(T, ValidationScores)]) -> Option<T> {
            Study::from_trials(candidates.to_vec(), |v| v.m_rms)
                .ok()
                .map(|s| *s.chosen())
        }
        let v = |m_rms, m_phys| ValidationScores { m_rms, m_phys };
        assert_eq!(
            lowest_m_rms(&[("constant", v(9.0, 1.0)), ("halve-on-plateau", v(8.5, 50.0))]),
            Some("halve-on-plateau")
        );
        assert_eq!(
            lowest_m_rms(&[("constant", v(8.0, 99.0)), ("halve-on-plateau", v(8.5, 1.0))]),
            Some("constant")
        );
        assert_eq!(lowest_m_rms::<&str>(&[]), None);
        // The stage-1 budget by the same rule.
        assert_eq!(
            lowest_m_rms(&[(30, v(25.0, 2611.0)), (150, v(12.4, 1104.0))]),
            Some(150)
        );
        assert_eq!(budget_candidates(Size::Quick, &quick), [quick.epochs[0]]);
    }

    /// The stage-3 rate study's model is the source model's stages 1 and 2 with its own
    /// stage 3; the stage-3 budget study's is the source's three stages, stage 3 trained on.
    /// Either copy leaves the source as it was, and the configuration's own candidate is the
    /// source model, kept.
    #[test]
    fn stage_3_study_models_share_the_source_stages_and_train_only_stage_3() {
        let quick = training_config(Size::Quick);
        assert_eq!(fine_tune_candidates(Size::Quick, &quick), [None]);
        let standard = training_config(Size::Standard);
        assert_eq!(fine_tune_candidates(Size::Standard, &standard), [None, Some(1e-4)]);
        assert_eq!(fine_tune_name(&standard, Some(1e-4)), "0.0001");
        assert_eq!(fine_tune_name(&standard, None), "0.001 (every stage's)");

        let data = EmbedData::new(simulated_sheet(20, false)).unwrap();
        let root = std::env::temp_dir().join(format!("weft-embed-fine-tune-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let ctx = EvalContext {
            quiet: true,
            ..EvalContext::new(Size::Quick, root.clone())
        };
        let config = EmbedTrainingSettings {
            epochs: [1, 1, 2],
            ..method_config(&quick, true)
        };
        let role = Role {
            scene: "sheet-ms",
            method: "no-pb",
            first_seed: false,
        };
        let (source, study) = (root.join("source"), root.join("study"));
        scored_model(&ctx, &data, &config, &source, role).unwrap();
        let state =
            |dir: &Path, stage: u8| std::fs::read(weft_nn::embed::stage_dir(dir, stage).join("training.json")).unwrap();
        let source_stage_3 = state(&source, 3);
        share_stages(&source, &study, 2).unwrap();
        assert!(!weft_nn::embed::stage_dir(&study, 3).exists());
        let slower = EmbedTrainingSettings {
            fine_tune_learning_rate: Some(1e-4),
            ..config.clone()
        };
        let scores = scored_model(&ctx, &data, &slower, &study, role).unwrap();
        assert_eq!(scores.config, slower);
        for stage in 1..=2 {
            assert_eq!(state(&study, stage), state(&source, stage), "stage {stage}");
        }
        assert_ne!(state(&study, 3), source_stage_3);
        assert_eq!(state(&source, 3), source_stage_3, "the source is untouched");
        let stored: EmbedTrainingSettings = weft_nn::checkpoint::read_json(&study.join("config.json")).unwrap();
        assert_eq!(stored.fine_tune_learning_rate, Some(1e-4));

        // The stage-3 budget study: a copy of all three stages whose stage 3 trains on is
        // the model a fresh directory trains with the longer budget, epoch for epoch.
        assert_eq!(stage_3_budget_candidates(Size::Quick, &quick), [quick.epochs[2]]);
        assert_eq!(
            stage_3_budget_candidates(Size::Standard, &standard),
            [10, STAGE_3_BUDGET_EPOCHS]
        );
        // Through the studies' own step: the configuration's candidate is the source
        // itself, kept; another is a copy under the study's directory.
        let kept = stage_3_candidate_runs(
            &ctx,
            &data,
            "sheet-ms",
            std::slice::from_ref(&config),
            std::slice::from_ref(&source),
            None,
        )
        .unwrap();
        assert_eq!(kept[0].0, source);
        assert_eq!(state(&source, 3), source_stage_3, "kept, not retrained");
        let four = EmbedTrainingSettings {
            epochs: [1, 1, 4],
            ..config.clone()
        };
        let copies = root.join("stage-3-budget-study").join("stage-3-4");
        let mut runs = stage_3_candidate_runs(
            &ctx,
            &data,
            "sheet-ms",
            std::slice::from_ref(&four),
            std::slice::from_ref(&source),
            Some((&copies, 3)),
        )
        .unwrap();
        let (longer, continued) = runs.remove(0);
        assert_eq!(longer, copies.join(format!("seed-{}", four.seed)));
        let straight = root.join("straight");
        let fresh = scored_model(&ctx, &data, &four, &straight, role).unwrap();
        // Stage 3's epochs: (loss, validation, wall seconds).
        let history = |dir: &Path| -> Vec<(f64, f64, f64)> {
            TrainingState::read(&weft_nn::embed::stage_dir(dir, 3))
                .unwrap()
                .history
                .iter()
                .map(|h| (h.loss, h.validation, h.train_seconds))
                .collect()
        };
        let without_time = |h: Vec<(f64, f64, f64)>| h.into_iter().map(|(l, v, _)| (l, v)).collect::<Vec<_>>();
        assert_eq!(history(&longer).len(), 4);
        assert_eq!(without_time(history(&longer)), without_time(history(&straight)));
        // Continued, not retrained: stages 1 and 2 are the copied runs, and stage 3's first
        // two epochs are the source's own (their wall times included).
        for stage in 1..=2 {
            assert_eq!(state(&longer, stage), state(&source, stage), "stage {stage}");
        }
        assert_eq!(history(&longer)[..2], history(&source)[..]);
        assert_eq!(continued.validation, fresh.validation);
        assert_eq!(state(&source, 3), source_stage_3, "the source is untouched");
        let _ = std::fs::remove_dir_all(&root);
    }
}
