//! The embed experiment's report: Tan et al.'s printed figures (Tables I, II and IV) and
//! the tables beside ours, the study and λ_ephys tables, the learning-curve plots and the
//! test records of each method. Reads scores; trains and scores nothing.

use std::path::Path;

use weft_data::Size;
use weft_nn::embed::EmbedTrainingSettings;
use weft_nn::ik::IkSettings;
use weft_nn::trainer::TrainingState;

use super::scoring::{PREDICTIONS_FILE, seeds_long_rollout};
use super::studies::{BUDGET_STUDY_EPOCHS, EPHYS_RMS_TOLERANCE, Run, STAGE_3_BUDGET_EPOCHS};
use super::{EARLY_STOPPING_PATIENCE, IkRow, Scene, SceneResults, Scores, Studies, scenes, seeds};
use crate::error::Context;
use crate::paper::{Table, format_ms, paper_cell as cell, with_spread};
use crate::records::{
    ExperimentOutput, Figure, LinePlot, Record, SeedFigure, Series, Timing, figure, lower_beyond_spread, mean_sd,
    three_significant_decimals,
};

/// Tan et al. Tables I and III: (scene, method, M_rms, M_STED, M_phys) as printed.
pub(super) const TABLE_I: [(&str, &str, f64, f64, f64); 20] = [
    ("sheet-ms", "ours", 9.724, 0.01556, 14581.46),
    ("sheet-ms", "no-pb", 10.351, 0.01688, 15446.70),
    ("sheet-ms-holes", "ours", 12.456, 0.02443, 19548.58),
    ("sheet-ms-holes", "no-pb", 12.928, 0.02480, 20632.13),
    ("sheet-fem", "ours", 10.671, 0.01398, 29109.03),
    ("sheet-fem", "no-pb", 10.675, 0.01195, 103878.20),
    ("sheet-fem-obstacle", "ours", 8.075, 0.01784, 160545.91),
    ("sheet-fem-obstacle", "no-pb", 8.425, 0.01885, 155117.28),
    ("ball-ms", "ours", 17.008, 0.02570, 338465.20),
    ("ball-ms", "no-pb", 20.326, 0.03018, 459564.89),
    ("ball-fem", "ours", 11.663, 0.01501, 49392520.44),
    ("ball-fem", "no-pb", 12.200, 0.01662, 61048220.56),
    ("ball-fem-soft-stretch", "ours", 16.853, 0.03394, 80389.68),
    ("ball-fem-soft-stretch", "no-pb", 17.706, 0.03357, 84508.12),
    ("ball-fem-soft-bend", "ours", 23.766, 0.04320, 674115.57),
    ("ball-fem-soft-bend", "no-pb", 27.390, 0.05320, 974481.48),
    // Table III's coarser sheets.
    ("sheet-ms-33", "ours", 11.744, 0.01511, 15712.89),
    ("sheet-ms-33", "no-pb", 11.842, 0.1648, 16076.44),
    ("sheet-ms-17", "ours", 11.757, 0.01273, 10565.27),
    ("sheet-ms-17", "no-pb", 12.510, 0.01543, 15498.58),
];

/// Tan et al. Table II (SHEET+[11] = `sheet-ms`): M_STED and M_phys for λ_ephys = 0.1,
/// 0.5, 1 and for "[46] + L_vert".
pub(super) const TABLE_II: [(&str, f64, f64); 4] = [
    ("(1, 1, 0.1)", 0.01712, 15164.34),
    ("(1, 1, 0.5)", 0.01635, 14230.44),
    ("(1, 1, 1)", 0.01556, 14581.46),
    ("[46] + L_vert", 0.01688, 15446.70),
];

/// Tan et al. Table IV: (scene, row, M_rms, M_STED, M_phys) of the 2-given, 3-predicted
/// roll-out test.
pub(super) const TABLE_IV: [(&str, &str, f64, f64, f64); 6] = [
    ("sheet-ms", "baseline", 15.184, 0.01765, 21019.28),
    ("sheet-ms", "2nd stage", 14.910, 0.01705, 18103.66),
    ("sheet-ms", "3rd stage", 14.000, 0.01672, 17819.85),
    ("sheet-ms-holes", "baseline", 18.843, 0.02703, 29673.30),
    ("sheet-ms-holes", "2nd stage", 17.909, 0.02667, 28526.89),
    ("sheet-ms-holes", "3rd stage", 17.412, 0.02633, 28393.81),
];

/// `paper / ours` cells of M_rms, M_STED and M_phys: the mean over `runs` (the seeds),
/// with their spread (`± sd`) where there are several.
pub(super) fn score_cells(paper: Option<(f64, f64, f64)>, runs: &[Scores]) -> [String; 3] {
    let metric: [(Option<f64>, fn(&Scores) -> f64, usize); 3] = [
        (paper.map(|p| p.0), |s| s.m_rms, 3),
        (paper.map(|p| p.1), |s| s.m_sted, 5),
        (paper.map(|p| p.2), |s| s.m_phys, 2),
    ];
    metric.map(|(paper, of, digits)| seeds_cell(paper, runs.iter().map(of), digits))
}

/// `paper / mean ± sd` of `samples` (one per seed), `digits` after the point; no spread for
/// one sample.
pub(super) fn seeds_cell(paper: Option<f64>, samples: impl Iterator<Item = f64>, digits: usize) -> String {
    let v: Vec<f64> = samples.collect();
    let (mean, sd) = mean_sd(v.iter().copied());
    with_spread(cell(paper, mean, digits), (v.len() > 1).then_some(sd), digits)
}

/// The header of a study's table: the candidate, [`study_row`]'s columns with `trained`
/// naming its last, and the choice.
pub(super) fn study_header(candidate: &str, trained: &str) -> Vec<String> {
    [
        candidate,
        "mean validation M_rms (mm)",
        "validation M_rms per seed (mm)",
        "validation M_phys per seed (N²)",
        trained,
        "chosen",
    ]
    .map(String::from)
    .to_vec()
}

/// A study's plot on `scene`: `no-pb`'s validation loss in `stage` under each candidate
/// (`(label, model directory)`, first seed).
pub(super) fn study_curves(
    scene: &str,
    study: &str,
    what: &str,
    curves: &[(String, std::path::PathBuf)],
    stage: u8,
) -> LinePlot {
    let curves: Vec<(&str, &Path)> = curves.iter().map(|(l, d)| (l.as_str(), d.as_path())).collect();
    stage_curves(
        format!("{scene}-{study}"),
        format!("embed / {scene}: `no-pb` stage-{stage} validation loss under each {what} (first seed)"),
        &curves,
        &[stage],
    )
}

/// The learning curves of `models` (method, model directory): each stage's validation loss
/// after every epoch (0: the stage's starting weights). Each stage has its own objective,
/// so the stages are separate lines.
pub(super) fn learning_curves(scene: &str, models: &[(&str, &Path)]) -> LinePlot {
    stage_curves(
        format!("{scene}-learning-curves"),
        format!("embed / {scene}: validation loss per epoch (first seed)"),
        models,
        &[1, 2, 3],
    )
}

/// The validation loss after every epoch of `stages` of each model, one line per model and
/// stage, as the plot `name`.
pub(super) fn stage_curves(name: String, title: String, models: &[(&str, &Path)], stages: &[u8]) -> LinePlot {
    let mut series = Vec::new();
    for (method, dir) in models {
        for &stage in stages {
            let Ok(state) = TrainingState::read(&weft_nn::embed::stage_dir(dir, stage)) else {
                continue;
            };
            let (mut x, mut y) = (vec![0.0], vec![state.initial_validation]);
            for h in &state.history {
                x.push(h.epoch as f64);
                y.push(h.validation);
            }
            series.push(Series {
                label: format!("{method}, stage {stage}"),
                x,
                y,
            });
        }
    }
    let log_y = series.iter().all(|s| s.y.iter().all(|v| *v > 0.0));
    LinePlot {
        name,
        title,
        x_label: "epoch of the stage".into(),
        y_label: "validation loss of the stage (each stage its own objective)".into(),
        log_y,
        series,
    }
}

pub(super) fn ik_table(rows: &[IkRow], settings: IkSettings) -> Table {
    Table {
        title: "Tan et al. §V-A — cloth inverse kinematics in latent space against the full space (ours only)".into(),
        caption: format!(
            "Each target pins the grasped vertices at a test frame's grasp positions; both solvers minimise the \
             elastic potential P_s + P_b (no gravity, no inertia) from the same start, `ours`'s decoding of the \
             dataset's first frame with those pins. Latent: Adam on the code, {} iterations, learning rate {}, \
             the lowest energy kept. Full space: weft-sim's Newton over every vertex with the scene's settings \
             (tolerance 1e-5 of the heaviest vertex's weight), at most 300 iterations; `unconverged` counts targets \
             where it stopped above the tolerance (flat directions without gravity). Means over the targets; the gap is M_rms between the two answers. The paper shows \
             examples (Fig. 2) but prints no figures.",
            settings.iterations, settings.learning_rate
        ),
        header: [
            "scene",
            "targets",
            "start P (J)",
            "latent P (J)",
            "full-space P (J)",
            "latent time",
            "full-space time (Newton iterations)",
            "unconverged",
            "gap (mm)",
        ]
        .map(String::from)
        .to_vec(),
        rows: rows
            .iter()
            .map(|r| {
                vec![
                    format!("`{}`", r.scene),
                    r.targets.to_string(),
                    format!("{:.4e}", r.start_energy),
                    format!("{:.4e}", r.latent_energy),
                    format!("{:.4e}", r.full_energy),
                    format_ms(r.latent_seconds),
                    format!("{} ({:.1})", format_ms(r.full_seconds), r.newton_iterations),
                    r.unconverged.to_string(),
                    format!("{:.2}", r.gap_mm),
                ]
            })
            .collect(),
    }
}

pub(super) fn tan_table_2(columns: &[(String, Vec<Scores>)]) -> Table {
    let paper = |label: &str| TABLE_II.iter().find(|t| t.0 == label).map(|t| (t.1, t.2));
    let mut header = vec!["metric".to_string()];
    header.extend(columns.iter().map(|(l, _)| l.clone()));
    let row = |name: &str, f: &dyn Fn(&str, &[Scores]) -> String| {
        let mut r = vec![name.to_string()];
        r.extend(columns.iter().map(|(l, runs)| f(l, runs)));
        r
    };
    Table {
        title: "Tan et al. Table II — sensitivity to the loss weights (λ_recon, λ_vert, λ_ephys), paper / ours".into(),
        caption:
            "`sheet-ms` (SHEET+[11]), test split, mean ± sd over the seeds. The paper prints no M_rms here. λ_mphys \
                  stays at the configuration's value for every PB-loss column."
                .into(),
        header,
        rows: vec![
            row("M_rms (mm)", &|_, runs| {
                seeds_cell(None, runs.iter().map(|s| s.m_rms), 3)
            }),
            row("M_STED", &|l, runs| {
                seeds_cell(paper(l).map(|p| p.0), runs.iter().map(|s| s.m_sted), 5)
            }),
            row("M_phys (N²)", &|l, runs| {
                seeds_cell(paper(l).map(|p| p.1), runs.iter().map(|s| s.m_phys), 2)
            }),
        ],
    }
}

pub(super) fn tan_table_4(rows: &[(String, String, Vec<Scores>)]) -> Table {
    Table {
        title: "Tan et al. Table IV — the latent simulator given 2 frames, predicting 3, paper / ours".into(),
        caption: "In each 5-frame test window the first two frames are encoded and the latent MLP predicts the \
                  other three from their controls, decoded to positions. Baseline: the \"[46] + L_vert\" model \
                  (λ_ephys = λ_mphys = 0); 2nd stage: `ours` before the stage-3 fine-tuning; 3rd stage: `ours`; \
                  pca + MLP: the same latent MLP trained on the codes of a PCA of the same size (ours only). \
                  M_rms over the predicted frames (mm), M_STED over the whole window, M_phys of the predicted \
                  frames (N²). Mean ± sd over the seeds (the MLP's own seeds for pca + MLP). The paper prints \
                  SHEET+[11] (`sheet-ms`) and +holes only."
            .into(),
        header: ["scene", "model", "M_rms", "M_STED", "M_phys"]
            .map(String::from)
            .to_vec(),
        rows: rows
            .iter()
            .map(|(scene, label, s)| {
                let paper = TABLE_IV
                    .iter()
                    .find(|t| t.0 == scene && t.1 == *label)
                    .map(|t| (t.2, t.3, t.4));
                let [a, b, c] = score_cells(paper, s);
                vec![format!("`{scene}`"), label.to_string(), a, b, c]
            })
            .collect(),
    }
}

/// Which of the learned embedding's figure and a linear baseline's is lower beyond the
/// spreads (`records::lower_beyond_spread`, the claim's rule): `Some(true)` the baseline,
/// `Some(false)` the embedding, `None` a tie.
pub(super) fn baseline_lower(ours: Figure, baseline: Figure) -> Option<bool> {
    if lower_beyond_spread(baseline, ours) {
        Some(true)
    } else if lower_beyond_spread(ours, baseline) {
        Some(false)
    } else {
        None
    }
}

/// Where a linear subspace beats the learned embedding (issue 31: the report "states
/// plainly where PCA or PCA + MLP beats the learned embedding and where it does not"):
/// per scene, `ours`'s test reconstructions against a PCA of the same latent size, and
/// Table IV's roll-out of `ours` (its 3rd stage) against the same latent MLP on the PCA
/// codes; the last row counts the scenes each way. Built from the test records and
/// Table IV's rows, so a run restored from its scene files draws it again.
pub(super) fn linear_baselines_table(records: &[Record], table_4: &[(String, String, Vec<Scores>)]) -> Table {
    const METRICS: [(&str, fn(&Scores) -> f64); 3] = [
        ("m-rms", |s| s.m_rms),
        ("m-sted", |s| s.m_sted),
        ("m-phys", |s| s.m_phys),
    ];
    let recorded =
        |scene: &str, method: &str, metric: &str| figure(records, |r| r.scene == scene && r.is_test(), method, metric);
    let rolled = |scene: &str, model: &str, of: fn(&Scores) -> f64| -> Option<Figure> {
        let runs = &table_4.iter().find(|(s, m, _)| s == scene && m == model)?.2;
        (!runs.is_empty()).then(|| mean_sd(runs.iter().map(of)))
    };
    // Per column: scenes where the baseline is lower, where `ours` is, and ties.
    let mut counts = [[0usize; 3]; 6];
    let mut rows = Vec::new();
    for &scene in scenes() {
        let pairs: Vec<Option<(Figure, Figure)>> = METRICS
            .iter()
            .map(|(metric, _)| Some((recorded(scene, "ours", metric)?, recorded(scene, "pca", metric)?)))
            .chain(
                METRICS
                    .iter()
                    .map(|(_, of)| Some((rolled(scene, "3rd stage", *of)?, rolled(scene, "pca + MLP", *of)?))),
            )
            .collect();
        if pairs.iter().all(Option::is_none) {
            continue;
        }
        let mut row = vec![format!("`{scene}`")];
        for (k, pair) in pairs.into_iter().enumerate() {
            let Some((ours, baseline)) = pair else {
                row.push("—".into());
                continue;
            };
            let digits = three_significant_decimals(ours.0.abs().min(baseline.0.abs()));
            // Both figures to the same decimals, so they compare at a glance; where the
            // smaller needs more than four (a PCA that reconstructs a ball exactly), each
            // in scientific notation instead of a dozen digits of the larger.
            let shown = |f: Figure| {
                if digits > 4 {
                    let spread = if f.1 > 0.0 {
                        format!(" ± {:.2e}", f.1)
                    } else {
                        String::new()
                    };
                    format!("{:.2e}{spread}", f.0)
                } else {
                    with_spread(format!("{:.digits$}", f.0), (f.1 > 0.0).then_some(f.1), digits)
                }
            };
            let lower = baseline_lower(ours, baseline);
            counts[k][match lower {
                Some(true) => 0,
                Some(false) => 1,
                None => 2,
            }] += 1;
            let name = if k < 3 { "PCA" } else { "PCA + MLP" };
            let verdict = match lower {
                Some(true) => name,
                Some(false) => "ours",
                None => "tie",
            };
            row.push(format!("{} vs {} → {verdict}", shown(ours), shown(baseline)));
        }
        rows.push(row);
    }
    let mut total = vec!["scenes where lower".to_string()];
    total.extend(counts.iter().enumerate().map(|(k, [b, o, t])| {
        let name = if k < 3 { "PCA" } else { "PCA + MLP" };
        format!("{name} {b} · ours {o} · tie {t}")
    }));
    rows.push(total);
    Table {
        title: "Tan et al. embedding against a linear subspace: where PCA and PCA + MLP beat it".into(),
        caption: "Test split, each cell `ours vs baseline → lower`. Reconstruction: `ours` (mean ± sd over the seeds) \
                  against a PCA with the same latent size fitted to the same training frames (one run, no spread). \
                  Roll-out: Table IV's 3rd stage (`ours`) against the same latent MLP trained on the PCA codes \
                  (pca + MLP, mean ± sd over its seeds). The lower method is named where it is lower by more than \
                  the two spreads together, `tie` where it is not; the last row counts the scenes. M_rms in mm, \
                  M_phys in N²."
            .into(),
        header: [
            "scene",
            "reconstruction M_rms",
            "reconstruction M_STED",
            "reconstruction M_phys",
            "roll-out M_rms",
            "roll-out M_STED",
            "roll-out M_phys",
        ]
        .map(String::from)
        .to_vec(),
        rows,
    }
}

/// The experiment's opening note: the networks, the schedule, the weights and the seeds.
pub(super) fn configuration_note(config: &EmbedTrainingSettings, size: Size) -> String {
    format!(
        "embed: {} graph convolution(s), {}-D latent, latent MLP hidden {:?}, epochs per stage {:?}, batch {}, \
         Adam lr {}; λ_ephys chosen per scene on the validation windows (the λ_ephys table; {} without a \
         choice), λ_mphys = {} for `ours`, 0 for `no-pb`; {} seed(s) per model (each figure their mean, its `-sd` \
         record their spread, the long roll-out's mean ± spread per frame; retrieval, scatter, predictions and \
         inverse kinematics from the first seed); PCA with the same \
         latent size, the PCA + MLP simulator with every seed; STED with the 1-ring, s = 1 m/s, c = 1",
        config.autoencoder.conv_layers,
        config.autoencoder.latent,
        config.latent_hidden,
        config.epochs,
        config.batch,
        config.adam.learning_rate,
        config.weights.ephys,
        config.weights.mphys,
        seeds(size).len(),
    )
}

/// A method's test figures on the scene: with `seeds` (one per run of `runs`), one record
/// per seed, their mean (beside Table I's figure where the paper has one) and their spread
/// as the `-sd` record; without (a PCA: one deterministic run), its figure alone.
pub(super) fn record_method(
    out: &mut ExperimentOutput,
    s: &Scene,
    method: &str,
    (seeds, runs): (&[u64], &[Scores]),
    seconds: f64,
) {
    let scene = s.name;
    let timing = Timing {
        seconds_per_frame: Some(seconds),
        ground_truth_seconds_per_frame: Some(s.gt_seconds),
    };
    let metrics: [(&str, &dyn Fn(&Scores) -> f64, &str); 3] = [
        ("m-rms", &|s| s.m_rms, "mm"),
        ("m-sted", &|s| s.m_sted, "1"),
        ("m-phys", &|s| s.m_phys, "N^2"),
    ];
    for (metric, of, unit) in metrics {
        let paper = TABLE_I
            .iter()
            .find(|t| t.0 == scene && t.1 == method)
            .map(|t| match metric {
                "m-rms" => t.2,
                "m-sted" => t.3,
                _ => t.4,
            });
        if seeds.is_empty() {
            out.record(scene, method, metric, of(&runs[0]), unit, timing);
            out.split("test");
            if let Some(p) = paper {
                out.paper(p);
            }
            continue;
        }
        let per_seed: Vec<(u64, f64)> = seeds.iter().copied().zip(runs.iter().map(of)).collect();
        let figure = SeedFigure {
            scene,
            method,
            metric,
            split: Some("test"),
            unit,
            timing,
            paper,
        };
        out.record_over_seeds(&figure, &per_seed);
    }
}

/// What a reported method (`ours` or `no-pb`, its seeds' `runs`, the first first) adds to
/// the scene: its long roll-out, scatter and inverse-kinematics rows, its first seed's
/// predictions under `predictions/`, its test records and its Table II and IV entries.
/// Returns its first seed's retrieval nDCG.
pub(super) fn report_method(s: &Scene, r: &mut SceneResults, method: &str, runs: &[Run]) -> crate::Result<f64> {
    let scene = s.name;
    let out = &mut r.output;
    let scores: Vec<Scores> = runs.iter().map(|(_, s)| s.test).collect();
    let rollouts: Vec<Scores> = runs.iter().map(|(_, s)| s.rollout).collect();
    let seconds = mean_sd(runs.iter().map(|(_, s)| s.seconds_per_frame)).0;
    let (dir, first_seed) = (&runs[0].0, &runs[0].1);
    s.write_reported(method, dir)?;
    let extras = first_seed.first_seed.as_ref().context("the first seed's plots")?;
    let long = seeds_long_rollout(scene, method, runs.iter().map(|(_, s)| s), out)?;
    out.curves.extend(long);
    out.scatters.extend(extras.scatter.clone());
    r.ik_rows.extend(extras.ik.clone());
    // The reported model's reconstructions; a model scored on another machine (its
    // scores kept, its weights not) has none here.
    let kept = dir.join(PREDICTIONS_FILE);
    if kept.exists() {
        let to = s.ctx.out.join("predictions").join("embed").join(scene);
        std::fs::create_dir_all(&to)?;
        std::fs::copy(&kept, to.join(format!("{method}.safetensors")))?;
    } else {
        out.notes.push(format!(
            "embed/{scene}: {method}'s predictions are not in predictions/ (the model was scored in an earlier \
             run whose weights were not kept)"
        ));
    }
    let seeds: Vec<u64> = runs.iter().map(|(_, s)| s.config.seed).collect();
    record_method(out, s, method, (&seeds, &scores), seconds);
    if method == "ours" {
        let snapshots: Vec<Scores> = runs
            .iter()
            .map(|(_, s)| s.stage_2_rollout.context("a PB-loss model's stage-2 roll-out"))
            .collect::<crate::Result<_>>()?;
        r.table_4.push((scene.into(), "2nd stage".into(), snapshots));
        r.table_4.push((scene.into(), "3rd stage".into(), rollouts));
    } else {
        // Table IV's baseline trains without L_mphys; ours has no such model
        // and uses the "[46] + L_vert" one (no physics in any stage).
        r.table_4.push((scene.into(), "baseline".into(), rollouts));
        if scene == "sheet-ms" {
            r.table_2.push(("[46] + L_vert".into(), scores.clone()));
        }
    }
    Ok(extras.ndcg)
}

/// The scene's closing note: its sizes, PCA's components and each method's retrieval nDCG.
pub(super) fn scene_note(s: &Scene, pca_components: usize, ndcg: &[(&str, f64)]) -> String {
    let paper = match s.name {
        "sheet-ms" => " (Tan et al. §VI-C: 0.8045)",
        "ball-ms" => " (Tan et al. §VI-C: 0.9128)",
        _ => "",
    };
    format!(
        "embed/{}: {} vertices, {} training windows, {} test frames, PCA kept {} components; nDCG of \
         motion-label retrieval in latent space over the full ranking: {}{paper}",
        s.name,
        s.data.num_vertices(),
        s.data.train_windows.len(),
        s.data.test_frames.len(),
        pca_components,
        ndcg.iter()
            .map(|(m, v)| format!("{m} {v:.4}"))
            .collect::<Vec<_>>()
            .join(", "),
    )
}

/// Every scene's rows and Table II and IV entries, in scene order.
#[derive(Default)]
struct Rows {
    ephys: Vec<(Vec<f64>, Vec<String>)>,
    table_2: Vec<(String, Vec<Scores>)>,
    table_4: Vec<(String, String, Vec<Scores>)>,
    ik: Vec<IkRow>,
    schedule: Vec<Vec<String>>,
    budget: Vec<Vec<String>>,
    fine_tune: Vec<Vec<String>>,
    stage_3_budget: Vec<Vec<String>>,
}

/// After the scenes (`done`, in order, their outputs already taken): the note on each
/// scene's wall seconds, then the experiment's tables — λ_ephys, the first scene's
/// studies, Tan et al.'s Tables II and IV, the linear baselines and inverse kinematics.
pub(super) fn push_tables(out: &mut ExperimentOutput, studies: &Studies, done: Vec<(&str, SceneResults)>) {
    let mut rows = Rows::default();
    let mut scene_seconds = Vec::new();
    for (scene, results) in done {
        rows.ephys.extend(results.ephys_row);
        rows.table_2.extend(results.table_2);
        rows.table_4.extend(results.table_4);
        rows.ik.extend(results.ik_rows);
        rows.schedule.extend(results.schedule_rows);
        rows.budget.extend(results.budget_rows);
        rows.fine_tune.extend(results.fine_tune_rows);
        rows.stage_3_budget.extend(results.stage_3_budget_rows);
        scene_seconds.push(format!("{scene} {:.0}", results.wall_seconds));
    }
    out.notes.push(format!(
        "embed: wall seconds of the run that finished each scene (models trained in earlier runs of the same \
         command are not in it; a scene remade from a file of an older format adds the remake to the run that \
         made the file): {}",
        scene_seconds.join(", ")
    ));
    // The paper's orders: λ_ephys ascending then the baseline; baseline, 2nd, 3rd stage.
    let mut table_2 = rows.table_2;
    table_2.sort_by_key(|(label, _)| TABLE_II.iter().position(|t| t.0 == label).unwrap_or(usize::MAX));
    let model_order = ["baseline", "2nd stage", "3rd stage", "pca + MLP"];
    let mut table_4 = rows.table_4;
    table_4.sort_by_key(|(scene, model, _)| {
        (
            scenes().iter().position(|s| s == scene),
            model_order.iter().position(|m| m == model),
        )
    });
    out.tables.extend(ephys_table(rows.ephys));
    out.tables.extend(study_tables(
        studies,
        rows.schedule,
        rows.budget,
        rows.fine_tune,
        rows.stage_3_budget,
    ));
    out.tables.push(tan_table_2(&table_2));
    out.tables.push(tan_table_4(&table_4));
    out.tables.push(linear_baselines_table(&out.records, &table_4));
    out.tables.push(ik_table(&rows.ik, IkSettings::default()));
}

/// The λ_ephys table: each scene's row of validation scores at its grid (none when no
/// scene had a choice to make).
fn ephys_table(rows: Vec<(Vec<f64>, Vec<String>)>) -> Option<Table> {
    let (grid, _) = rows.first()?;
    let mut header = vec!["scene".to_string()];
    header.push("parity λ*".into());
    header.extend((1..=grid.len()).map(|i| format!("λ_ephys #{i}")));
    header.push("no-pb".into());
    header.push("chosen".into());
    Some(Table {
        title: "Tan et al. λ_ephys chosen per scene on the validation windows".into(),
        caption: format!(
            "Validation M_rms (mm) / M_phys (N²) of the first seed of `ours` at each λ_ephys (`λ: M_rms / \
             M_phys`) and of `no-pb`. The grid is `no-pb`'s parity λ* (the weight at which L_ephys pulls a \
             frame as hard as L_vert, docs/EMBEDDING.md) to one significant digit and a decade either side. \
             The chosen weight has the lowest M_phys among those within {} % of `no-pb`'s M_rms (else the \
             lowest M_rms). The other seeds train at it; the test split plays no part.",
            100.0 * EPHYS_RMS_TOLERANCE
        ),
        header,
        rows: rows.into_iter().map(|(_, r)| r).collect(),
    })
}

/// The first scene's study tables, in the order the studies ran (a study that did not
/// run has no rows and no table).
fn study_tables(
    studies: &Studies,
    schedule_rows: Vec<Vec<String>>,
    budget_rows: Vec<Vec<String>>,
    fine_tune_rows: Vec<Vec<String>>,
    stage_3_budget_rows: Vec<Vec<String>>,
) -> Vec<Table> {
    let first = scenes()[0];
    let mut tables = Vec::new();
    if !schedule_rows.is_empty() {
        tables.push(Table {
            title: "Tan et al. learning-rate schedule chosen on the validation windows".into(),
            caption: format!(
                "`no-pb`, every seed, on `{first}`: validation M_rms (mm) and M_phys (N²) after training under each \
                 schedule (every stage stops once its validation loss has not improved for {EARLY_STOPPING_PATIENCE} \
                 epochs), and the epochs each stage trained (the kept epoch in brackets). The schedule with the lowest \
                 mean validation M_rms trains every model, and its models are the scene's `no-pb`; the test split \
                 plays no part."
            ),
            header: study_header("schedule", "epochs per seed, stages 1 / 2 / 3 (kept epoch)"),
            rows: schedule_rows,
        });
    }
    if !budget_rows.is_empty() {
        let configured = studies.budgets[0];
        tables.push(Table {
            title: "Tan et al. stage-1 budget chosen on the validation windows".into(),
            caption: format!(
                "`no-pb`, first seed, on `{first}`, under the chosen schedule, with the configuration's {configured} stage-1 epochs and with \
                 up to {BUDGET_STUDY_EPOCHS} (every stage still stops once its validation loss has not improved for \
                 {EARLY_STOPPING_PATIENCE} epochs; the kept epoch in brackets). An epoch here is 320 training windows \
                 (4 sequences of 170 frames), the paper's about 1400 (one sequence of 2400), so an epoch here is about \
                 4.4 times fewer steps than one there. Validation \
                 M_rms (mm) and M_phys (N²); the budget with the lower validation M_rms trains every model; the test \
                 split plays no part."
            ),
            header: [
                "stage-1 epochs allowed",
                "epochs, stages 1 / 2 / 3",
                "validation M_rms (mm)",
                "validation M_phys (N²)",
                "training seconds",
                "chosen",
            ]
            .map(String::from)
            .to_vec(),
            rows: budget_rows,
        });
    }
    if !fine_tune_rows.is_empty() {
        tables.push(Table {
            title: "Tan et al. stage-3 learning rate chosen on the validation windows".into(),
            caption: format!(
                "`no-pb`, every seed, on `{first}`, under the chosen schedule and budget: stage 3 (both networks \
                 fine-tuned from a fresh Adam) trained from the same stages 1 and 2 under each learning rate. \
                 Validation M_rms (mm) and M_phys (N²) of the stage-3 model, and the epochs stage 3 trained (the \
                 kept epoch in brackets; 0 keeps the stage-2 weights). The rate with the lowest mean validation \
                 M_rms fine-tunes every model; the test split plays no part."
            ),
            header: study_header("stage-3 learning rate", "stage-3 epochs per seed (kept epoch)"),
            rows: fine_tune_rows,
        });
    }
    if !stage_3_budget_rows.is_empty() {
        tables.push(Table {
            title: "Tan et al. stage-3 budget chosen on the validation windows".into(),
            caption: format!(
                "`no-pb`, every seed, on `{first}`, under the chosen schedule, stage-1 budget and stage-3 rate: stage 3 \
                 with Tan et al.'s epochs and with up to {STAGE_3_BUDGET_EPOCHS} (the longer run continues the \
                 shorter one; every stage stops once its validation loss has not improved for \
                 {EARLY_STOPPING_PATIENCE} epochs). Validation M_rms (mm) and M_phys (N²) of the stage-3 model, and \
                 the epochs stage 3 trained (the kept epoch in brackets). The budget with the lowest mean validation \
                 M_rms fine-tunes every model; the test split plays no part."
            ),
            header: study_header("stage-3 epochs allowed", "stage-3 epochs per seed (kept epoch)"),
            rows: stage_3_budget_rows,
        });
    }
    tables
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluate::embed::tests::simulated_sheet;
    use crate::evaluate::embed::*;
    use weft_nn::embed::EmbedData;

    /// The learning curves read each stage's training state: one line per method and stage,
    /// starting at the stage's initial validation loss, the epochs in order.
    #[test]
    fn learning_curves_have_a_line_per_trained_stage_from_its_starting_weights() {
        let data = EmbedData::new(simulated_sheet(20, false)).unwrap();
        let dir = std::env::temp_dir().join(format!("weft-embed-curves-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let config = EmbedTrainingSettings {
            epochs: [2, 0, 1],
            ..training_config(Size::Quick)
        };
        weft_nn::embed::train_model(&dir, &data, &config, &[1, 2, 3], &mut weft_nn::trainer::Silent).unwrap();
        let plot = learning_curves("sheet-ms", &[("ours", &dir)]);
        let labels: Vec<&str> = plot.series.iter().map(|s| s.label.as_str()).collect();
        assert_eq!(labels, ["ours, stage 1", "ours, stage 3"]);
        let first = TrainingState::read(&weft_nn::embed::stage_dir(&dir, 1)).unwrap();
        assert_eq!(plot.series[0].x, [0.0, 1.0, 2.0]);
        assert_eq!(plot.series[0].y[0], first.initial_validation);
        assert_eq!(plot.series[0].y[2], first.history[1].validation);
        assert_eq!(plot.series[1].x, [0.0, 1.0]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Table II and IV cells: the mean over the seeds with the population spread, the
    /// paper's figure first; one seed has no spread.
    #[test]
    fn seed_cells_print_the_mean_and_spread_beside_the_paper() {
        assert_eq!(
            seeds_cell(Some(9.724), [10.0, 12.0, 14.0].into_iter(), 3),
            "9.724 / 12.000 ± 1.633"
        );
        assert_eq!(seeds_cell(None, [2.5].into_iter(), 2), "— / 2.50");
        let s = |m_rms, m_sted, m_phys| Scores { m_rms, m_sted, m_phys };
        let cells = score_cells(Some((1.0, 0.5, 100.0)), &[s(2.0, 0.1, 10.0), s(4.0, 0.3, 30.0)]);
        assert_eq!(
            cells,
            [
                "1.000 / 3.000 ± 1.000",
                "0.50000 / 0.20000 ± 0.10000",
                "100.00 / 20.00 ± 10.00"
            ]
        );
    }

    /// The linear-baselines table names the lower method only beyond both spreads, reads
    /// reconstructions from the test records (not the validation ones) and roll-outs from
    /// Table IV's rows, and counts the scenes each way.
    #[test]
    fn the_linear_baselines_table_names_the_lower_method_beyond_the_spreads() {
        let mut out = ExperimentOutput::new("embed", Size::Standard);
        let mut test = |method: &str, metric: &str, value: f64| {
            out.record("sheet-ms", method, metric, value, "", Timing::default());
            out.records.last_mut().unwrap().split = Some("test".into());
        };
        // PCA lower by far; `ours` lower by more than its spread; a tie.
        test("ours", "m-rms", 6.0);
        test("ours", "m-rms-sd", 1.0);
        test("pca", "m-rms", 0.2);
        test("ours", "m-phys", 200.0);
        test("ours", "m-phys-sd", 10.0);
        test("pca", "m-phys", 250.0);
        test("ours", "m-sted", 0.020);
        test("ours", "m-sted-sd", 0.01);
        test("pca", "m-sted", 0.025);
        // A validation record that must not be read as the test figure.
        out.record("sheet-ms", "pca", "m-rms", 100.0, "", Timing::default());
        out.records.last_mut().unwrap().split = Some("validation".into());
        let s = |m_rms, m_sted, m_phys| Scores { m_rms, m_sted, m_phys };
        let table_4 = vec![
            (
                "sheet-ms".to_string(),
                "3rd stage".to_string(),
                vec![s(5.0, 0.1, 300.0), s(7.0, 0.1, 310.0)],
            ),
            (
                "sheet-ms".to_string(),
                "pca + MLP".to_string(),
                vec![s(6.5, 0.3, 100.0), s(6.5, 0.3, 100.0)],
            ),
            ("ball-ms".to_string(), "3rd stage".to_string(), vec![s(1.0, 0.1, 1.0)]),
        ];
        let table = linear_baselines_table(&out.records, &table_4);
        assert_eq!(table.header.len(), 7);
        assert_eq!(table.rows.len(), 2, "{:?}", table.rows);
        let row = &table.rows[0];
        assert_eq!(row[0], "`sheet-ms`");
        assert_eq!(row[1], "6.000 ± 1.000 vs 0.200 → PCA");
        assert_eq!(row[2], "0.0200 ± 0.0100 vs 0.0250 → tie");
        assert_eq!(row[3], "200 ± 10 vs 250 → ours");
        assert_eq!(row[4], "6.00 ± 1.00 vs 6.50 → tie");
        assert_eq!(row[5], "0.100 vs 0.300 → ours");
        assert_eq!(row[6], "305 ± 5 vs 100 → PCA + MLP");
        // `ball-ms` has no PCA + MLP row and no records: it is left out.
        assert_eq!(
            table.rows[1][1..],
            [
                "PCA 1 · ours 0 · tie 0",
                "PCA 0 · ours 0 · tie 1",
                "PCA 0 · ours 1 · tie 0",
                "PCA + MLP 0 · ours 0 · tie 1",
                "PCA + MLP 0 · ours 1 · tie 0",
                "PCA + MLP 1 · ours 0 · tie 0",
            ]
        );
        // A PCA that reconstructs exactly: scientific notation, not twelve decimals.
        let mut out = ExperimentOutput::new("embed", Size::Standard);
        for (method, metric, value) in [
            ("ours", "m-phys", 772.28),
            ("ours", "m-phys-sd", 223.53),
            ("pca", "m-phys", 4.73e-8),
        ] {
            out.record("ball-fem", method, metric, value, "", Timing::default());
            out.records.last_mut().unwrap().split = Some("test".into());
        }
        let exact = linear_baselines_table(&out.records, &[]);
        assert_eq!(exact.rows[0][3], "7.72e2 ± 2.24e2 vs 4.73e-8 → PCA");
        assert_eq!(baseline_lower((1.0, 0.1), (1.0, 0.0)), None);
        assert_eq!(baseline_lower((1.0, 0.0), (0.5, 0.5)), None);
        assert_eq!(baseline_lower((1.0, 0.0), (0.5, 0.4)), Some(true));
    }
}
