//! Experiment `embed`: Tan et al.'s mesh embedding with PB-loss (`ours`), without it
//! (`no-pb`, "\[46\] + L_vert") and PCA on positions (`pca`), on the design's eight cloth
//! scenes. Each scene's dataset is generated (`cargo xtask dataset`) and both networks
//! trained (`cargo xtask train embed`) into `OUT/embed/`, resuming whatever an earlier run
//! left there. Metrics on the test split (the last 5 of every 17 frames): M_rms, M_STED per
//! 5-frame window, and M_phys on frames whose two predecessors are in their window, with
//! the method's own reconstructions as predecessors (docs/RESULTS.md).
//!
//! One file per phase: `data` the scenes' datasets and frame sets, `studies` what is
//! chosen on the validation windows (the first scene's schedule, budgets and stage-3
//! studies, each scene's λ_ephys), `scoring` training and scoring one model and the
//! metrics, `tables` the paper's tables, the plots and the records, `diagnostics` issue 71's
//! gradient norms and M_phys floor (`cargo xtask embed-diagnostics`). This module holds the
//! experiment's entry, its types and the loop over the scenes. The networks and their
//! training are weft-nn's (`weft_nn::embed`), not this module's.

mod data;
mod diagnostics;
mod scoring;
mod studies;
mod tables;

use std::path::{Path, PathBuf};
use std::time::Instant;

use weft_nn::embed::EmbedTrainingSettings;
use weft_nn::trainer::Schedule;

use super::context::EvalContext;
use crate::records::{Curve, ExperimentOutput, Scatter};
use weft_data::Size;

pub use diagnostics::{
    CheckpointNorms, FloorReport, FloorRow, GradientLog, RegionResidual, gradient_log, mphys_floor, mphys_floor_of,
    near_grasp, projected_residual,
};
pub use scoring::score_model;
use studies::{budget_candidates, fine_tune_candidates, schedule_candidates, stage_3_budget_candidates};

/// The design's eight cloth scenes (Tan et al.'s SHEET and BALL datasets, Table I) and
/// the two coarser sheets of the resolution study (Table III): every built-in cloth scene.
fn scenes() -> &'static [&'static str] {
    &weft_sim::BUILTIN_SCENES
}

/// The training configuration of each evaluation size. `standard` and `paper` train for
/// the paper's schedule (epochs 30, 30, 10), each stage stopping early once its validation
/// loss has not improved for [`EARLY_STOPPING_PATIENCE`] epochs (issue 31: "train to
/// convergence"); the learning-rate schedule is then chosen on validation
/// ([`schedule_candidates`]). `quick` shrinks the networks and trains a fixed budget.
fn training_config(size: Size) -> EmbedTrainingSettings {
    let mut c = EmbedTrainingSettings::default();
    match size {
        Size::Quick => {
            c.autoencoder.conv_layers = 1;
            c.autoencoder.latent = 16;
            c.latent_hidden = vec![64];
            c.epochs = [20, 20, 5];
            c.adam.learning_rate = 2e-3;
        }
        Size::Standard | Size::Paper => {
            c.schedule.early_stopping_patience = Some(EARLY_STOPPING_PATIENCE);
        }
    }
    c
}

/// Epochs without a better validation loss after which a stage stops (standard and paper
/// sizes): the validation loss has flattened. Stage 1's validation loss spikes for one to
/// three epochs on its way down (up to 2.4 times its trend on `sheet-ms`), so 5 epochs ended
/// runs that were still descending: `ours` (λ_ephys 0.1) at epoch 31 with a validation loss
/// of 83, while `no-pb` went on to 23 by epoch 68 and a second seed to 10 by epoch 131.
/// Twenty epochs without a new best is a flat curve, not a spike (docs/EMBEDDING.md).
const EARLY_STOPPING_PATIENCE: usize = 20;

/// What the first scene chooses on its validation windows before the other models train,
/// each study's candidates in order (the configuration's first).
#[derive(Debug, Clone)]
struct Studies {
    schedules: Vec<(&'static str, Schedule)>,
    budgets: Vec<usize>,
    fine_tune: Vec<Option<f64>>,
    stage_3_budgets: Vec<usize>,
}

impl Studies {
    fn new(size: Size, config: &EmbedTrainingSettings) -> Self {
        Self {
            schedules: schedule_candidates(size, config),
            budgets: budget_candidates(size, config),
            fine_tune: fine_tune_candidates(size, config),
            stage_3_budgets: stage_3_budget_candidates(size, config),
        }
    }
}

/// Seeds per model: one at quick size (CI), three otherwise.
fn seeds(size: Size) -> Vec<u64> {
    match size {
        Size::Quick => vec![0],
        _ => vec![0, 1, 2],
    }
}

/// `config` with its seed (initial weights and window order) set to `seed`.
fn with_seed(config: &EmbedTrainingSettings, seed: u64) -> EmbedTrainingSettings {
    EmbedTrainingSettings { seed, ..config.clone() }
}

/// The configuration a method trains under: `no-pb` zeroes the physics weights.
fn method_config(config: &EmbedTrainingSettings, no_pb: bool) -> EmbedTrainingSettings {
    let mut c = config.clone();
    if no_pb {
        c.weights.ephys = 0.0;
        c.weights.mphys = 0.0;
    }
    c
}

/// A model's M_rms (mm) and M_phys (N²) on the validation windows: each window's frame
/// and its two predecessors reconstructed, M_rms of the frame, M_phys of the frame with
/// the reconstructed predecessors (as on the test split). Only validation and training
/// frames are read.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
struct ValidationScores {
    m_rms: f64,
    m_phys: f64,
}

#[derive(Debug, Clone, Copy, serde::Serialize, serde::Deserialize)]
struct Scores {
    m_rms: f64,
    m_sted: f64,
    m_phys: f64,
}

/// One row of the inverse-kinematics table: means over the targets.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct IkRow {
    scene: String,
    targets: usize,
    start_energy: f64,
    latent_energy: f64,
    full_energy: f64,
    latent_seconds: f64,
    full_seconds: f64,
    newton_iterations: f64,
    /// Targets where Newton stopped above its tolerance (the energy is its last iterate's).
    unconverged: usize,
    /// M_rms between the latent and the full-space answers (mm).
    gap_mm: f64,
}

/// What the experiment reads of one trained model, computed once after training and kept
/// beside it as `scores.json`. Nothing later needs the weights, so a run carried to another
/// machine by its small files (docs/EMBEDDING.md, "A run that spans machines") does not
/// retrain the models it has scored.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct ModelScores {
    /// The configuration the model trained under (a model of another is retrained).
    config: EmbedTrainingSettings,
    validation: ValidationScores,
    test: Scores,
    /// Seconds per test frame to reconstruct (encode and decode).
    seconds_per_frame: f64,
    /// Table IV's roll-out test.
    rollout: Scores,
    /// The roll-out test of the model after stage 2 (PB-loss models: Table IV's "2nd stage").
    stage_2_rollout: Option<Scores>,
    /// Tan et al. §V-B's long roll-out ([`long_rollout`]), every seed's, so the plot has a
    /// spread. `None` only for a model scored before it was kept whose weights are gone.
    #[serde(default)]
    long_rollout: Option<Curve>,
    /// What a method's first seed adds: retrieval, plots, inverse kinematics.
    first_seed: Option<FirstSeed>,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct FirstSeed {
    ndcg: f64,
    scatter: Option<Scatter>,
    ik: Option<IkRow>,
}

/// A model's place in the report: its scene, the method it is reported as, and whether it
/// is that method's first seed (which draws the plots and writes the predictions).
#[derive(Debug, Clone, Copy)]
struct Role<'a> {
    scene: &'a str,
    method: &'a str,
    first_seed: bool,
}

/// One model to train (unless its scores are kept) and score: its configuration,
/// directory and role.
#[derive(Clone)]
struct Job<'a> {
    config: EmbedTrainingSettings,
    dir: PathBuf,
    role: Role<'a>,
}

impl<'a> Job<'a> {
    fn new(config: EmbedTrainingSettings, dir: PathBuf, role: Role<'a>) -> Self {
        Self { config, dir, role }
    }
}

/// Everything one scene adds to the experiment's output, kept as `embed/scenes/<scene>.json`
/// once the scene is done: a later run under the same configuration reads it instead of
/// generating the dataset and scoring the models again.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
struct SceneResults {
    /// The experiment's configuration after the scene (the first scene chooses the
    /// learning-rate schedule).
    config: EmbedTrainingSettings,
    /// The scene's records, curves, scatters, learning curves, notes and failures.
    output: ExperimentOutput,
    ephys_row: Option<(Vec<f64>, Vec<String>)>,
    /// Table II's columns and Table IV's rows, each with its scores per seed.
    table_2: Vec<(String, Vec<Scores>)>,
    table_4: Vec<(String, String, Vec<Scores>)>,
    ik_rows: Vec<IkRow>,
    schedule_rows: Vec<Vec<String>>,
    /// The budget study's rows (first scene, beyond the quick size).
    #[serde(default)]
    budget_rows: Vec<Vec<String>>,
    /// The stage-3 learning-rate study's rows (first scene, beyond the quick size).
    #[serde(default)]
    fine_tune_rows: Vec<Vec<String>>,
    /// The stage-3 budget study's rows (first scene, beyond the quick size).
    #[serde(default)]
    stage_3_budget_rows: Vec<Vec<String>>,
    /// Wall seconds of the run that finished the scene (its models may have trained in
    /// earlier runs).
    wall_seconds: f64,
    /// The file's format ([`SCENE_FORMAT`]).
    #[serde(default)]
    format: u32,
}

/// The format of a scene's kept results. A file of an older format is remade from its
/// models' kept scores (nothing retrains): 1 holds every seed's long roll-out, where 0
/// held the first seed's; 2 holds a record per seed of every learned figure
/// (`records::record_over_seeds`), where 1 held only their mean and spread.
const SCENE_FORMAT: u32 = 2;

/// What a scene's kept file gives a later run.
#[derive(Debug)]
enum KeptScene {
    /// Nothing usable: run the scene.
    Run,
    /// The scene's results, made under the run's configuration.
    Done(Box<SceneResults>),
    /// Made under the run's configuration in an older format: remake it from the models'
    /// kept scores, counting the seconds the earlier run spent on it.
    Remake { earlier_seconds: f64 },
}

/// The results kept at `path` if they were made under `config` (on the first scene, under
/// any candidate schedule and stage-1 budget: the scene makes the choices).
fn restored_scene(path: &Path, config: &EmbedTrainingSettings, studies: &Studies, first: bool) -> KeptScene {
    let Ok(text) = std::fs::read_to_string(path) else {
        return KeptScene::Run;
    };
    let kept: SceneResults = match serde_json::from_str(&text) {
        Ok(k) => k,
        Err(e) => {
            eprintln!("embed: {} does not parse ({e}); running the scene", path.display());
            return KeptScene::Run;
        }
    };
    let same = if first {
        let mut before_the_studies = EmbedTrainingSettings {
            schedule: config.schedule,
            fine_tune_learning_rate: config.fine_tune_learning_rate,
            ..kept.config.clone()
        };
        before_the_studies.epochs[0] = config.epochs[0];
        before_the_studies.epochs[2] = config.epochs[2];
        studies.schedules.iter().any(|(_, s)| *s == kept.config.schedule)
            && studies.budgets.contains(&kept.config.epochs[0])
            && studies.stage_3_budgets.contains(&kept.config.epochs[2])
            && studies.fine_tune.contains(&kept.config.fine_tune_learning_rate)
            && before_the_studies == *config
    } else {
        kept.config == *config
    };
    if !same {
        KeptScene::Run
    } else if kept.format != SCENE_FORMAT {
        eprintln!(
            "embed: {} is of an older format ({}, now {SCENE_FORMAT}); remaking the scene from its models' scores",
            path.display(),
            kept.format
        );
        KeptScene::Remake {
            earlier_seconds: kept.wall_seconds,
        }
    } else {
        KeptScene::Done(Box::new(kept))
    }
}

/// One scene's run: its dataset and where its models live.
struct Scene<'a> {
    ctx: &'a EvalContext,
    name: &'a str,
    data: weft_nn::embed::EmbedData,
    /// The simulator's seconds per frame, every method's timing reference.
    gt_seconds: f64,
    seeds: Vec<u64>,
    /// `OUT/embed/models/<scene>`.
    models: PathBuf,
}

/// The model a scene reports as `method` (its first seed; for `ours`, at the λ_ephys chosen
/// on validation), named in `OUT/embed/models/<scene>/reported-<method>.json` relative to
/// the scene's models: what another experiment loads (`guarded`'s embed surrogate).
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct ReportedModel {
    dir: PathBuf,
}

fn reported_path(models: &Path, method: &str) -> PathBuf {
    models.join(format!("reported-{method}.json"))
}

/// The directory of the model the embed experiment under `out` reported as `method` on
/// `scene`, if a run wrote one ([`ReportedModel`]); its weights may be gone (a model
/// scored on another machine).
pub(crate) fn reported_model(out: &Path, scene: &str, method: &str) -> Option<PathBuf> {
    let models = out.join("embed").join("models").join(scene);
    let r: ReportedModel = weft_nn::checkpoint::read_json(&reported_path(&models, method)).ok()?;
    Some(models.join(r.dir))
}

impl<'a> Scene<'a> {
    /// Names `dir` as the model reported as `method` ([`reported_model`]).
    fn write_reported(&self, method: &str, dir: &Path) -> crate::Result<()> {
        let dir = dir.strip_prefix(&self.models).unwrap_or(dir).to_path_buf();
        Ok(weft_data::files::write_json(
            &reported_path(&self.models, method),
            &ReportedModel { dir },
        )?)
    }

    /// The directory of `method`'s model with `seed`.
    fn seed_dir(&self, method: &str, seed: u64) -> PathBuf {
        self.models.join(method).join(format!("seed-{seed}"))
    }

    fn role(&self, method: &'a str, first_seed: bool) -> Role<'a> {
        Role {
            scene: self.name,
            method,
            first_seed,
        }
    }
}

impl SceneResults {
    /// A scene's results before any model: nothing but the configuration.
    fn new(config: &EmbedTrainingSettings, size: Size) -> Self {
        Self {
            config: config.clone(),
            output: ExperimentOutput::new("embed", size),
            ephys_row: None,
            table_2: Vec::new(),
            table_4: Vec::new(),
            ik_rows: Vec::new(),
            schedule_rows: Vec::new(),
            budget_rows: Vec::new(),
            fine_tune_rows: Vec::new(),
            stage_3_budget_rows: Vec::new(),
            wall_seconds: 0.0,
            format: SCENE_FORMAT,
        }
    }
}

pub fn run(ctx: &EvalContext) -> crate::Result<ExperimentOutput> {
    let mut out = ExperimentOutput::new("embed", ctx.size);
    let root = ctx.out.join("embed");
    let mut config = training_config(ctx.size);
    std::fs::create_dir_all(root.join("scenes"))?;
    let config_path = root.join("config.json");
    std::fs::write(&config_path, serde_json::to_string_pretty(&config)?)?;
    out.notes.push(tables::configuration_note(&config, ctx.size));
    out.seeds = seeds(ctx.size).len();
    let studies = Studies::new(ctx.size, &config);
    let mut done = Vec::new();
    for (i, &scene) in scenes().iter().enumerate() {
        let (mut results, earlier_seconds) = finished_scene(ctx, scene, &config, &studies, i == 0)?;
        out.wall_seconds += earlier_seconds;
        if results.config != config {
            config = results.config.clone();
            std::fs::write(&config_path, serde_json::to_string_pretty(&config)?)?;
        }
        let o = std::mem::replace(&mut results.output, ExperimentOutput::new("embed", ctx.size));
        out.records.extend(o.records);
        out.curves.extend(o.curves);
        out.scatters.extend(o.scatters);
        out.lines.extend(o.lines);
        out.notes.extend(o.notes);
        out.failures.extend(o.failures);
        done.push((scene, results));
    }
    tables::push_tables(&mut out, &studies, done);
    Ok(out)
}

/// A scene's results (its output still in them) and the seconds earlier runs spent on it:
/// read back if a run finished it under `config`, else run (or remade) now and kept.
fn finished_scene(
    ctx: &EvalContext,
    scene: &str,
    config: &EmbedTrainingSettings,
    studies: &Studies,
    first: bool,
) -> crate::Result<(SceneResults, f64)> {
    let path = ctx.out.join("embed").join("scenes").join(format!("{scene}.json"));
    // The seconds earlier runs spent on the scene count in the experiment's (this run's own
    // are the driver's to add).
    match restored_scene(&path, config, studies, first) {
        KeptScene::Done(r) => {
            eprintln!("embed/{scene}: read from {} (done in an earlier run)", path.display());
            let seconds = r.wall_seconds;
            Ok((*r, seconds))
        }
        kept => {
            let earlier_seconds = match kept {
                KeptScene::Remake { earlier_seconds } => earlier_seconds,
                _ => 0.0,
            };
            let t = Instant::now();
            let mut r = run_scene(ctx, scene, config, studies, first)?;
            r.wall_seconds = earlier_seconds + t.elapsed().as_secs_f64();
            weft_data::files::write_json(&path, &r)?;
            Ok((r, earlier_seconds))
        }
    }
}

/// One scene of the experiment: its dataset, every model trained (or resumed) and scored,
/// PCA and PCA + MLP; on the first scene, the studies choose the schedule, the budgets and
/// stage 3's rate first.
fn run_scene(
    ctx: &EvalContext,
    scene: &str,
    config: &EmbedTrainingSettings,
    studies: &Studies,
    first: bool,
) -> crate::Result<SceneResults> {
    let mut r = SceneResults::new(config, ctx.size);
    let models = ctx.out.join("embed").join("models").join(scene);
    let (data, gt_seconds) = data::scene_data(ctx, scene, &mut r.output)?;
    let s = Scene {
        ctx,
        name: scene,
        data,
        gt_seconds,
        seeds: seeds(ctx.size),
        models,
    };
    let study = if first {
        studies::run_studies(&s, studies, &mut r)?
    } else {
        Vec::new()
    };
    let (baseline, ours) = studies::baseline_and_ours(&s, &study, &mut r)?;
    r.output.lines.push(tables::learning_curves(
        scene,
        &[("ours", &ours[0].0), ("no-pb", &baseline[0].0)],
    ));
    let mut ndcg: Vec<(&str, f64)> = Vec::new();
    for (method, runs) in [("ours", &ours), ("no-pb", &baseline)] {
        ndcg.push((method, tables::report_method(&s, &mut r, method, runs)?));
    }
    if scene == "sheet-ms" {
        studies::table_2_models(&s, &mut r)?;
    }
    let (pca_ndcg, components) = scoring::pca_baselines(&s, &mut r)?;
    ndcg.push(("pca", pca_ndcg));
    r.output.notes.push(tables::scene_note(&s, components, &ndcg));
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::studies::{BUDGET_STUDY_EPOCHS, STAGE_3_BUDGET_EPOCHS};
    use super::*;
    use weft_data::ClothDataset;

    /// A one-sequence `sheet-ms` dataset of `frames` simulated frames, in memory; with
    /// `poison`, every test frame (not one of Tan et al.'s training frames) is scaled by
    /// 1.5 — a split no choice made on validation may notice.
    pub(super) fn simulated_sheet(frames: usize, poison: bool) -> ClothDataset {
        let scene = weft_sim::ClothScene::builtin("sheet-ms", true).unwrap();
        let mut dataset = ClothDataset::simulate("sheet-ms", scene, frames).unwrap();
        let n = 3 * dataset.rest.num_vertices();
        for (m, frame) in dataset.sequences[0].positions.chunks_mut(n).enumerate() {
            if poison && !weft_data::is_train_frame(m) {
                frame.iter_mut().for_each(|x| *x *= 1.5);
            }
        }
        dataset
    }

    /// A finished scene is read back only under the configuration it ran with; the first
    /// scene's, under whichever candidate schedule and stage-1 budget it chose, and those
    /// choices are adopted.
    #[test]
    fn a_finished_scene_is_read_back_only_under_its_configuration() {
        let dir = std::env::temp_dir().join(format!("weft-embed-scene-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("sheet-ms.json");
        let config = training_config(Size::Standard);
        let schedules = schedule_candidates(Size::Standard, &config);
        let chosen = EmbedTrainingSettings {
            schedule: schedules[1].1,
            epochs: [BUDGET_STUDY_EPOCHS, 30, STAGE_3_BUDGET_EPOCHS],
            fine_tune_learning_rate: Some(1e-4),
            ..config.clone()
        };
        let results = |config: &EmbedTrainingSettings| SceneResults {
            ephys_row: Some((vec![0.1, 0.5], vec!["`sheet-ms`".into()])),
            table_4: vec![(
                "sheet-ms".into(),
                "baseline".into(),
                vec![Scores {
                    m_rms: 1.0,
                    m_sted: 0.01,
                    m_phys: 3.0,
                }],
            )],
            wall_seconds: 12.0,
            ..SceneResults::new(config, Size::Standard)
        };
        let budgets = budget_candidates(Size::Standard, &config);
        assert_eq!(budgets, [30, BUDGET_STUDY_EPOCHS]);
        let studies = Studies {
            schedules: schedules.clone(),
            budgets: budgets.clone(),
            fine_tune: fine_tune_candidates(Size::Standard, &config),
            stage_3_budgets: stage_3_budget_candidates(Size::Standard, &config),
        };
        assert_eq!(studies.fine_tune, [None, Some(1e-4)]);
        let restored = |c: &EmbedTrainingSettings, first| match restored_scene(&path, c, &studies, first) {
            KeptScene::Done(r) => Some(*r),
            _ => None,
        };
        assert!(restored(&config, true).is_none(), "no file");
        weft_data::files::write_json(&path, &results(&chosen)).unwrap();
        let first = restored(&config, true).unwrap();
        assert_eq!(first.config, chosen, "the first scene's choices are adopted");
        assert_eq!(first.table_4[0].2[0].m_phys, 3.0);
        assert!(restored(&chosen, false).is_some());
        assert!(restored(&config, false).is_none());
        // A file of an older format is remade, whatever its configuration.
        let older = SceneResults {
            format: SCENE_FORMAT - 1,
            ..results(&chosen)
        };
        weft_data::files::write_json(&path, &older).unwrap();
        assert!(matches!(
            restored_scene(&path, &chosen, &studies, false),
            KeptScene::Remake { earlier_seconds } if earlier_seconds == 12.0
        ));
        assert!(matches!(
            restored_scene(&path, &config, &studies, false),
            KeptScene::Run
        ));
        weft_data::files::write_json(&path, &results(&chosen)).unwrap();
        let mut more = config.clone();
        more.epochs[1] += 1;
        assert!(restored(&more, true).is_none());
        for odd in [
            EmbedTrainingSettings {
                schedule: Schedule {
                    early_stopping_patience: Some(9),
                    ..chosen.schedule
                },
                ..chosen.clone()
            },
            EmbedTrainingSettings {
                epochs: [77, 30, 10],
                ..chosen.clone()
            },
            EmbedTrainingSettings {
                epochs: [BUDGET_STUDY_EPOCHS, 30, 20],
                ..chosen.clone()
            },
            EmbedTrainingSettings {
                fine_tune_learning_rate: Some(0.5),
                ..chosen.clone()
            },
        ] {
            weft_data::files::write_json(&path, &results(&odd)).unwrap();
            assert!(restored(&config, true).is_none(), "not a candidate: {odd:?}");
        }
        std::fs::write(&path, "{").unwrap();
        assert!(restored(&config, true).is_none());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The committed cache of the standard run (`checkpoints/evaluate-standard`, what a
    /// republication reads instead of retraining) holds no model of another configuration
    /// than its scene's: outside the studies' own directories, every kept `scores.json`
    /// was trained under the scene's epochs, stage-3 rate and schedule — a stale model
    /// would be mixed into the `find … scores.json` readings of docs/EMBEDDING.md.
    #[test]
    fn the_committed_cache_holds_no_model_of_another_configuration_than_its_scene() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../checkpoints/evaluate-standard/embed");
        let read =
            |p: &Path| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap() };
        let key = |config: &serde_json::Value| {
            (
                config["epochs"].clone(),
                config["fine_tune_learning_rate"].clone(),
                config["schedule"].clone(),
            )
        };
        let mut checked = 0;
        for scene in std::fs::read_dir(root.join("scenes")).unwrap() {
            let path = scene.unwrap().path();
            let name = path.file_stem().unwrap().to_string_lossy().to_string();
            let expected = key(&read(&path)["config"]);
            for method in std::fs::read_dir(root.join("models").join(&name)).unwrap() {
                let method = method.unwrap().path();
                if method.file_name().unwrap().to_string_lossy().ends_with("-study") {
                    continue;
                }
                for seed in std::fs::read_dir(&method).unwrap() {
                    let scores = seed.unwrap().path().join("scores.json");
                    if scores.exists() {
                        assert_eq!(key(&read(&scores)["config"]), expected, "{} is stale", scores.display());
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked >= 60, "only {checked} kept models checked");
    }
}
