//! Training and scoring one embed model, and the metrics: M_rms, M_STED and M_phys on the
//! test windows and the validation windows, Table IV's roll-out, the long roll-out,
//! retrieval nDCG, the latent-code scatter, inverse kinematics, the linear baselines
//! (PCA, PCA + MLP) and `cargo xtask score`'s entry ([`score_model`]). Not the choices
//! between models ([`super::studies`]) nor the tables ([`super::tables`]).

use std::path::{Path, PathBuf};
use std::time::Instant;

use weft_data::ClothDataset;
use weft_nn::embed::LatentRollout;
use weft_nn::embed::{EmbedData, EmbedModel, EmbedTrainingSettings, FrameRef};
use weft_nn::ik::{IkSettings, decode_pinned, full_space_ik, latent_ik};
use weft_nn::metrics::{RmsAccumulator, StedParams, ndcg_curve, sted};
use weft_nn::pca::PositionPca;
use weft_nn::pca_simulator::{PcaSimulator, PcaSimulatorSettings};
use weft_sim::ForceResidual;

use super::data::{validation_frames, windows, write_predictions};
use super::studies::ephys_parity;
use super::{FirstSeed, IkRow, Job, ModelScores, Role, Scene, SceneResults, Scores, ValidationScores};
use super::{data, tables};
use crate::error::Context;
use crate::evaluate::context::{EvalContext, Scoring};
use crate::records::{Curve, ExperimentOutput, Scatter, Timing};

pub(super) fn validation_scores(data: &EmbedData, model: &EmbedModel) -> crate::Result<ValidationScores> {
    Ok(validation_breakdown(data, model)?.0)
}

/// [`validation_scores`] and the mean over the validation windows of M_phys's two forces
/// squared apart ([`weft_sim::ImplicitEuler::m_phys_parts`]).
pub(super) fn validation_breakdown(
    data: &EmbedData,
    model: &EmbedModel,
) -> crate::Result<(ValidationScores, ForceResidual)> {
    let frames = validation_frames(data)?;
    let predicted = model.reconstruct(data, &frames, 16)?;
    let windows = &data.validation_windows;
    let map: Vec<usize> = (0..data.num_vertices()).collect();
    let mut acc = RmsAccumulator::default();
    for (w, p) in windows.iter().zip(predicted.chunks_exact(3)) {
        acc.add(&p[2], data.dataset.sequences[w.sequence].frame(w.frame), &map);
    }
    let parts = mean_force_residual(data, &predicted)?;
    let scores = ValidationScores {
        m_rms: acc.m_rms_mm(),
        m_phys: parts.total,
    };
    Ok((scores, parts))
}

/// The mean over the validation windows of M_phys's parts, each window's three frames
/// taken from `positions` (laid out as [`validation_frames`]).
pub(super) fn mean_force_residual(data: &EmbedData, positions: &[Vec<f64>]) -> crate::Result<ForceResidual> {
    let windows = &data.validation_windows;
    let mut sum = ForceResidual {
        total: 0.0,
        inertial: 0.0,
        potential: 0.0,
    };
    for (w, p) in windows.iter().zip(positions.chunks_exact(3)) {
        let r = m_phys_parts(data, &p[0], &p[1], &p[2], *w)?;
        sum.total += r.total;
        sum.inertial += r.inertial;
        sum.potential += r.potential;
    }
    let n = windows.len() as f64;
    Ok(ForceResidual {
        total: sum.total / n,
        inertial: sum.inertial / n,
        potential: sum.potential / n,
    })
}

/// Whether `dir` holds a model that cannot be trained on into the one `config` asks for:
/// one from an older version of the experiment. A model that stopped under fewer epochs or
/// a shorter early-stopping patience is not stale: training it on gives exactly the model
/// `config` trains ([`weft_nn::embed::continues_exactly`]).
pub(super) fn stale(dir: &Path, config: &EmbedTrainingSettings) -> bool {
    dir.join("config.json").exists() && !weft_nn::embed::continues_exactly(dir, config)
}

/// Makes `to` a model directory holding `from`'s configuration, normalisation and trained
/// stages 1 and 2 (copies, so neither model's later training touches the other's files),
/// for a stage 3 trained under another learning rate
/// ([`weft_nn::embed::train_model`] then discards nothing and trains stage 3).
pub(super) fn share_stages(from: &Path, to: &Path, through: u8) -> crate::Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("creating {}", to.display()))?;
    for stage in 1..=through {
        let run = weft_nn::embed::stage_dir(from, stage);
        if run.exists() {
            crate::files::copy_tree(&run, &weft_nn::embed::stage_dir(to, stage))?;
        }
    }
    // The configuration last: a directory with it is a model (a copy cut short is redone).
    for file in ["normalization.json", "config.json"] {
        std::fs::copy(from.join(file), to.join(file))
            .with_context(|| format!("copying {} to {}", from.join(file).display(), to.display()))?;
    }
    Ok(())
}

/// Trains (or resumes) one model of the experiment into `dir`, all three stages; a model
/// trained under another configuration is discarded and retrained (it is the
/// experiment's own output, rebuilt by the same command).
pub(super) fn train(
    ctx: &EvalContext,
    data: &EmbedData,
    config: &EmbedTrainingSettings,
    dir: &Path,
) -> crate::Result<()> {
    if stale(dir, config) {
        eprintln!(
            "embed: {} was trained under another configuration; retraining it",
            dir.display()
        );
        std::fs::remove_dir_all(dir).with_context(|| format!("removing {}", dir.display()))?;
    }
    let label = format!("embed/{}", dir.display());
    // The model's method and seed directories name it among models training at once.
    let tag: Vec<String> = dir
        .iter()
        .rev()
        .take(2)
        .map(|c| c.to_string_lossy().into_owned())
        .collect();
    let tag = tag.into_iter().rev().collect::<Vec<_>>().join("/");
    let mut progress = crate::progress::TrainProgress::new(ctx.quiet, &label)?.tagged(tag);
    weft_nn::embed::train_model(dir, data, config, &[1, 2, 3], &mut progress)
        .with_context(|| format!("training {}", dir.display()))?;
    Ok(())
}

pub(super) const SCORES_FILE: &str = "scores.json";

/// A first seed's test reconstructions, kept in its model directory until the scene knows
/// which model it reports (the λ_ephys choice), then copied to `predictions/`.
pub(super) const PREDICTIONS_FILE: &str = "test-predictions.safetensors";

/// [`scored_models`] with each model's directory beside its scores.
pub(super) fn scored_runs(
    ctx: &EvalContext,
    data: &EmbedData,
    jobs: &[Job],
) -> crate::Result<Vec<(PathBuf, ModelScores)>> {
    let scores = scored_models(ctx, data, jobs)?;
    Ok(jobs.iter().map(|j| j.dir.clone()).zip(scores).collect())
}

/// [`scored_model`] for models that do not depend on each other, up to `ctx.jobs` at once
/// ([`EvalContext::concurrently`]); their scores in `jobs`' order.
pub(super) fn scored_models(ctx: &EvalContext, data: &EmbedData, jobs: &[Job]) -> crate::Result<Vec<ModelScores>> {
    ctx.concurrently(jobs.len(), |i| {
        scored_model(ctx, data, &jobs[i].config, &jobs[i].dir, jobs[i].role)
    })
}

/// Trains (or resumes) the model in `dir` and scores it, or reads the scores an earlier run
/// kept for the same configuration.
pub(super) fn scored_model(
    ctx: &EvalContext,
    data: &EmbedData,
    config: &EmbedTrainingSettings,
    dir: &Path,
    role: Role,
) -> crate::Result<ModelScores> {
    let path = dir.join(SCORES_FILE);
    if let Ok(mut kept) = weft_nn::checkpoint::read_json::<ModelScores>(&path) {
        if config.trains_like(&kept.config) && (kept.first_seed.is_some() || !role.first_seed) {
            // Scores kept before every seed's long roll-out was: add it where the weights
            // still are (the roll-out is deterministic), else report the seeds that have one.
            if kept.long_rollout.is_none()
                && let Ok(model) = EmbedModel::load(dir, data, 3)
            {
                kept.long_rollout = Some(long_rollout(role.scene, role.method, data, &model)?);
                weft_nn::checkpoint::write_json(&path, &kept)?;
            }
            return Ok(kept);
        }
    }
    train(ctx, data, config, dir)?;
    let model = EmbedModel::load(dir, data, 3)?;
    // Timed alone: another model may be training beside this one (`--jobs`).
    let (predicted, seconds) = crate::evaluate::context::timed_alone(|| {
        let t = Instant::now();
        model
            .reconstruct(data, &data.test_frames, 16)
            .map(|p| (p, t.elapsed().as_secs_f64()))
    })?;
    let seconds_per_frame = seconds / predicted.len().max(1) as f64;
    let pb = role.method == "ours";
    let stage_2_rollout = if pb {
        Some(rollout_scores(data, &EmbedModel::load(dir, data, 2)?)?)
    } else {
        None
    };
    let first_seed = if role.first_seed {
        write_predictions(&dir.join(PREDICTIONS_FILE), data, &predicted)?;
        let codes = model.codes(data, &data.test_frames)?;
        Some(FirstSeed {
            ndcg: full_ranking_ndcg(data, &codes)?,
            scatter: if pb && matches!(role.scene, "sheet-ms" | "ball-ms") {
                Some(embedding_scatter(role.scene, role.method, data, &codes)?)
            } else {
                None
            },
            ik: if pb && IK_SCENES.contains(&role.scene) {
                // Its rows report the latent and full-space solves' wall times.
                Some(crate::evaluate::context::timed_alone(|| {
                    inverse_kinematics(role.scene, data, &model)
                })?)
            } else {
                None
            },
        })
    } else {
        None
    };
    let scores = ModelScores {
        config: config.clone(),
        validation: validation_scores(data, &model)?,
        test: score(data, &predicted)?,
        seconds_per_frame,
        rollout: rollout_scores(data, &model)?,
        stage_2_rollout,
        long_rollout: Some(long_rollout(role.scene, role.method, data, &model)?),
        first_seed,
    };
    weft_nn::checkpoint::write_json(&path, &scores)?;
    Ok(scores)
}

/// Frames of one test window, predicted beside the ground truth; frames before
/// `scored_from` were given to the method (the roll-out test's first two).
pub(super) struct Window {
    predicted: Vec<Vec<f64>>,
    truth: Vec<Vec<f64>>,
    /// The dataset frame of each entry (its controls `q_m` prescribe M_phys's grasp).
    refs: Vec<FrameRef>,
    scored_from: usize,
}

/// Tan et al.'s M_phys of `p` as docs/RESULTS.md defines it: the force residual
/// `‖∂L_phys/∂p_m‖²` over the free DOFs with the grasped DOFs prescribed to the frame's
/// controls `q_m` (Eq. 9 evaluates the potential at `(p_m, q_m)`), whatever positions the
/// method put there. A method that pins its grasp (`ours`, `no-pb`) is scored at its own
/// positions; one that does not (`pca`) is not charged twice for the miss, which M_rms
/// already counts. N².
pub(super) fn m_phys(data: &EmbedData, prev2: &[f64], prev1: &[f64], p: &[f64], at: FrameRef) -> crate::Result<f64> {
    Ok(m_phys_parts(data, prev2, prev1, p, at)?.total)
}

/// [`m_phys`] with its inertial and potential forces squared apart.
pub(super) fn m_phys_parts(
    data: &EmbedData,
    prev2: &[f64],
    prev1: &[f64],
    p: &[f64],
    at: FrameRef,
) -> crate::Result<ForceResidual> {
    let q = data.dataset.sequences[at.sequence].control(at.frame);
    let prescribed = data.dataset.with_grasp_at(p, q)?;
    Ok(data.integrator.m_phys_parts(prev2, prev1, &prescribed)?)
}

/// M_rms over the scored frames, M_STED per window (all its frames), and M_phys of every
/// scored frame from the third of its window on, with the window's own frames as its
/// predecessors (docs/RESULTS.md).
pub(super) fn score_windows(data: &EmbedData, windows: &[Window]) -> crate::Result<Scores> {
    let map: Vec<usize> = (0..data.num_vertices()).collect();
    let edges = weft_mesh::Topology::new(&data.dataset.rest).edges;
    let params = StedParams {
        speed: 1.0,
        temporal_weight: 1.0,
        dt: data.dataset.scene.dt,
    };
    let mut acc = RmsAccumulator::default();
    let (mut sted_sum, mut phys_sum, mut phys_n) = (0.0, 0.0, 0usize);
    for w in windows {
        for (p, t) in w.predicted.iter().zip(&w.truth).skip(w.scored_from) {
            acc.add(p, t, &map);
        }
        sted_sum += sted(&edges, &w.truth, &w.predicted, params)?.combined;
        for i in w.scored_from.max(2)..w.predicted.len() {
            phys_sum += m_phys(
                data,
                &w.predicted[i - 2],
                &w.predicted[i - 1],
                &w.predicted[i],
                w.refs[i],
            )?;
            phys_n += 1;
        }
    }
    Ok(Scores {
        m_rms: acc.m_rms_mm(),
        m_sted: sted_sum / windows.len().max(1) as f64,
        m_phys: phys_sum / phys_n.max(1) as f64,
    })
}

/// The test split's scores of reconstructions `predicted` (one per test frame).
pub(super) fn score(data: &EmbedData, predicted: &[Vec<f64>]) -> crate::Result<Scores> {
    let frames = &data.test_frames;
    let windows: Vec<Window> = windows(frames)
        .into_iter()
        .map(|w| Window {
            predicted: w.iter().map(|&k| predicted[k].clone()).collect(),
            truth: w
                .iter()
                .map(|&k| {
                    data.dataset.sequences[frames[k].sequence]
                        .frame(frames[k].frame)
                        .to_vec()
                })
                .collect(),
            refs: w.iter().map(|&k| frames[k]).collect(),
            scored_from: 0,
        })
        .collect();
    score_windows(data, &windows)
}

/// nDCG over the full ranking (K = N − 1) of the test frames' codes by their motion
/// labels (Tan et al. §VI-C; docs/RESULTS.md).
pub(super) fn full_ranking_ndcg(data: &EmbedData, codes: &[Vec<f64>]) -> crate::Result<f64> {
    let labels: Vec<u8> = data
        .test_frames
        .iter()
        .map(|f| data.dataset.sequences[f.sequence].labels[f.frame])
        .collect();
    let curve = ndcg_curve(codes, &labels)?;
    Ok(*curve.last().context("fewer than two test frames")?)
}

/// A latent roll-out started from the encoded ground-truth frames `start`.
pub(super) fn rollout_from<'a>(
    data: &EmbedData,
    model: &'a EmbedModel,
    start: [FrameRef; 2],
) -> crate::Result<LatentRollout<'a>> {
    let codes = model.codes(data, &start)?;
    Ok(LatentRollout::new(
        &model.autoencoder,
        &model.simulator,
        data.inverse.clone(),
        data.normalization.clone(),
        &codes[0],
        &codes[1],
    )?)
}

/// Tan et al. Table IV's test: in each 5-frame test window, encode the first two frames,
/// let the latent simulator predict the other three from their controls and decode them
/// (`LatentRollout`); the scores of the predicted frames (the given two count in M_STED's
/// window and as M_phys's predecessors).
pub(super) fn rollout_scores(data: &EmbedData, model: &EmbedModel) -> crate::Result<Scores> {
    rollout_test(data, |start, _, controls| {
        let mut rollout = rollout_from(data, model, start)?;
        controls.iter().map(|c| Ok(rollout.step(c)?)).collect()
    })
}

/// Table IV's test for the latent MLP on the PCA subspace: in each 5-frame test window, the
/// first two frames' PCA codes start the MLP, which predicts the other three from their
/// controls, decoded through the basis; scored like [`rollout_scores`].
pub(super) fn pca_rollout_scores(data: &EmbedData, sim: &PcaSimulator) -> crate::Result<Scores> {
    rollout_test(data, |_, given, controls| {
        Ok(sim.rollout(&given[0], &given[1], controls)?)
    })
}

/// Table IV's test of a simulator: in each 5-frame test window, `predict` is given the
/// first two frames (their references and ground-truth positions) and the other three's
/// controls, and returns those three frames; scored from the third frame on, the given two
/// in M_STED's window and as M_phys's predecessors.
fn rollout_test(
    data: &EmbedData,
    mut predict: impl FnMut([FrameRef; 2], &[Vec<f64>], &[&[f64]]) -> crate::Result<Vec<Vec<f64>>>,
) -> crate::Result<Scores> {
    let frames = &data.test_frames;
    let mut scored = Vec::new();
    for w in windows(frames) {
        if w.len() < 5 {
            continue;
        }
        let truth: Vec<Vec<f64>> = w[..5]
            .iter()
            .map(|&k| {
                data.dataset.sequences[frames[k].sequence]
                    .frame(frames[k].frame)
                    .to_vec()
            })
            .collect();
        let controls: Vec<&[f64]> = w[2..5]
            .iter()
            .map(|&k| data.dataset.sequences[frames[k].sequence].control(frames[k].frame))
            .collect();
        let mut predicted = truth[..2].to_vec();
        predicted.extend(predict([frames[w[0]], frames[w[1]]], &truth[..2], &controls)?);
        scored.push(Window {
            predicted,
            truth,
            refs: w[..5].iter().map(|&k| frames[k]).collect(),
            scored_from: 2,
        });
    }
    score_windows(data, &scored)
}

/// [`long_rollout`] for the latent MLP on the PCA subspace.
pub(super) fn pca_long_rollout(scene: &str, data: &EmbedData, sim: &PcaSimulator) -> crate::Result<Curve> {
    let seq = &data.dataset.sequences[0];
    let controls: Vec<&[f64]> = (2..seq.num_frames()).map(|m| seq.control(m)).collect();
    let predicted = sim.rollout(seq.frame(0), seq.frame(1), &controls)?;
    let map: Vec<usize> = (0..data.num_vertices()).collect();
    let mut curve = Curve {
        scene: scene.into(),
        method: "pca-mlp".into(),
        frames: Vec::new(),
        error_mm: Vec::new(),
        error_mm_sd: Vec::new(),
    };
    for (k, p) in predicted.iter().enumerate() {
        let mut acc = RmsAccumulator::default();
        curve.frames.push((k + 2) as f64);
        curve.error_mm.push(acc.add(p, seq.frame(k + 2), &map));
    }
    Ok(curve)
}

/// Tan et al. §V-B: a latent roll-out of the whole first sequence from the codes of its
/// frames 0 and 1 and its controls, every frame decoded; the per-frame M_rms against the
/// ground truth shows how the error grows with the number of frames N.
pub(super) fn long_rollout(scene: &str, method: &str, data: &EmbedData, model: &EmbedModel) -> crate::Result<Curve> {
    let seq = &data.dataset.sequences[0];
    let mut rollout = rollout_from(data, model, [0, 1].map(|frame| FrameRef { sequence: 0, frame }))?;
    let map: Vec<usize> = (0..data.num_vertices()).collect();
    let mut curve = Curve {
        scene: scene.into(),
        method: method.into(),
        frames: Vec::new(),
        error_mm: Vec::new(),
        error_mm_sd: Vec::new(),
    };
    for m in 2..seq.num_frames() {
        let p = rollout.step(seq.control(m))?;
        let mut acc = RmsAccumulator::default();
        curve.frames.push(m as f64);
        curve.error_mm.push(acc.add(&p, seq.frame(m), &map));
    }
    Ok(curve)
}

/// `method`'s long roll-out over the seeds of `runs` that have one (a note names the
/// seeds that do not: scored on another machine before every seed's was kept).
pub(super) fn seeds_long_rollout<'a>(
    scene: &str,
    method: &str,
    runs: impl Iterator<Item = &'a ModelScores>,
    out: &mut ExperimentOutput,
) -> crate::Result<Option<Curve>> {
    let (mut curves, mut missing) = (Vec::new(), Vec::new());
    for s in runs {
        match &s.long_rollout {
            Some(c) => curves.push(Curve {
                method: method.into(),
                ..c.clone()
            }),
            None => missing.push(s.config.seed),
        }
    }
    if !missing.is_empty() {
        out.notes.push(format!(
            "embed/{scene}: {method}'s long roll-out is over {} seed(s); seeds {missing:?} were scored in an earlier \
             run whose weights were not kept",
            curves.len()
        ));
    }
    Curve::over_seeds(&curves)
}

/// Tan et al. Fig. 6: the test frames' latent codes projected on their two principal
/// axes, coloured by motion label.
pub(super) fn embedding_scatter(
    scene: &str,
    method: &str,
    data: &EmbedData,
    codes: &[Vec<f64>],
) -> crate::Result<Scatter> {
    let pca = PositionPca::fit(codes, 2)?;
    Ok(Scatter {
        scene: scene.into(),
        method: method.into(),
        title: format!("embed / {scene}: {method}'s latent codes of the test frames"),
        x_label: "first principal axis of the codes".into(),
        y_label: "second principal axis".into(),
        points: codes
            .iter()
            .map(|c| {
                let p = pca.encode(c);
                [p[0], p.get(1).copied().unwrap_or(0.0)]
            })
            .collect(),
        labels: data
            .test_frames
            .iter()
            .map(|f| {
                let code = data.dataset.sequences[f.sequence].labels[f.frame];
                weft_sim::MotionLabel::ALL
                    .get(code as usize)
                    .map_or_else(|| format!("label {code}"), |l| l.as_str().to_string())
            })
            .collect(),
    })
}

/// The scenes of the cloth inverse-kinematics study (the paper shows sheets, Fig. 2).
pub(super) const IK_SCENES: [&str; 2] = ["sheet-ms", "sheet-fem"];

/// Inverse-kinematics targets per scene: the grasp positions of the first frame of this
/// many test windows, spread over the test split.
pub(super) const IK_TARGETS: usize = 6;

/// Tan et al. §V-A: for each target (new grasp positions from a test frame), minimise
/// `P_s + P_b` over `ours`'s code from the code of the dataset's first frame, and over
/// every vertex with weft-sim's Newton solver from the same start positions.
pub(super) fn inverse_kinematics(scene: &str, data: &EmbedData, model: &EmbedModel) -> crate::Result<IkRow> {
    let groups = windows(&data.test_frames);
    let step = groups.len().div_ceil(IK_TARGETS).max(1);
    let z0 = model.codes(data, &[FrameRef { sequence: 0, frame: 0 }])?.remove(0);
    let map: Vec<usize> = (0..data.num_vertices()).collect();
    let mut row = IkRow {
        scene: scene.into(),
        targets: 0,
        start_energy: 0.0,
        latent_energy: 0.0,
        full_energy: 0.0,
        latent_seconds: 0.0,
        full_seconds: 0.0,
        newton_iterations: 0.0,
        unconverged: 0,
        gap_mm: 0.0,
    };
    let mut gap = RmsAccumulator::default();
    for w in groups.iter().step_by(step) {
        let f = data.test_frames[w[0]];
        let pins: Vec<nalgebra::Vector3<f64>> = data.dataset.sequences[f.sequence]
            .control(f.frame)
            .chunks_exact(3)
            .map(|c| nalgebra::Vector3::new(c[0], c[1], c[2]))
            .collect();
        let latent = latent_ik(model, data, &z0, &pins, IkSettings::default())?;
        let x0 = decode_pinned(model, data, &z0, &pins)?;
        let (full, converged) = full_space_ik(&data.integrator, &x0, 300)?;
        row.unconverged += usize::from(!converged);
        row.targets += 1;
        row.start_energy += latent.start_energy;
        row.latent_energy += latent.energy;
        row.full_energy += full.energy;
        row.latent_seconds += latent.seconds;
        row.full_seconds += full.seconds;
        row.newton_iterations += full.iterations as f64;
        gap.add(&latent.positions, &full.positions, &map);
    }
    let n = row.targets.max(1) as f64;
    for v in [
        &mut row.start_energy,
        &mut row.latent_energy,
        &mut row.full_energy,
        &mut row.latent_seconds,
        &mut row.full_seconds,
        &mut row.newton_iterations,
    ] {
        *v /= n;
    }
    row.gap_mm = gap.m_rms_mm();
    Ok(row)
}

/// Scores the model in `model_dir` (`cargo xtask train embed`) on the cloth dataset in
/// `data_dir`. The features are normalised by the model's own `normalization.json`, so a
/// dataset of another seed or size is read as the model was trained. The method is
/// `ours`, or `no-pb` for a model trained without the physics terms.
///
/// - `test`: Tan et al.'s test frames (the last 5 of every 17, §VI), with the
///   evaluation's metrics (`m-rms`, `m-sted`, `m-phys`) and its reconstructions under
///   `ctx.out/predictions/embed/<scene>/`.
/// - `validation`: the validation windows the evaluation chooses on (each frame with its
///   two predecessors reconstructed), `m-rms` and `m-phys` as the choice reads them, and
///   M_phys's two forces squared apart (`m-phys-inertial`, `m-phys-potential`), beside the
///   same three of the ground-truth frames (method `ground-truth`): how large the forces
///   are that the residual is measured against.
pub fn score_model(scoring: &Scoring) -> crate::Result<ExperimentOutput> {
    let (ctx, model_dir, data_dir, split) = (scoring.ctx, scoring.model_dir, scoring.data_dir, scoring.split);
    if !matches!(split, "test" | "validation") {
        return Err(crate::Error::Invalid(format!(
            "embed models are scored on Tan et al.'s test frames (the last 5 of every 17) or on the validation windows, not {split:?}: use --split test or --split validation"
        )));
    }
    let dataset = ClothDataset::load(data_dir)?;
    let scene = dataset.name.clone();
    let normalization = weft_nn::checkpoint::read_json(&model_dir.join("normalization.json"))?;
    let data = EmbedData::with_normalization(dataset, normalization)?;
    let model = scoring.load_model(|dir| EmbedModel::load(dir, &data, 3))?;
    let w = model.config.weights;
    let method = if w.ephys == 0.0 && w.mphys == 0.0 {
        "no-pb"
    } else {
        "ours"
    };
    if split == "validation" {
        return score_validation(ctx, model_dir, &scene, method, &data, &model);
    }
    let t = Instant::now();
    let predicted = model.reconstruct(&data, &data.test_frames, 16)?;
    let seconds = t.elapsed().as_secs_f64() / predicted.len().max(1) as f64;
    let scores = score(&data, &predicted)?;
    let timing = Timing {
        seconds_per_frame: Some(seconds),
        ground_truth_seconds_per_frame: scoring.ground_truth_seconds(),
    };
    let mut out = scoring.output(format_args!(
        "({method}) on the {} test frames of {}",
        data.test_frames.len(),
        data_dir.display()
    ));
    for (metric, value, unit) in [
        ("m-rms", scores.m_rms, "mm"),
        ("m-sted", scores.m_sted, "1"),
        ("m-phys", scores.m_phys, "N^2"),
    ] {
        out.record(&scene, method, metric, value, unit, timing);
        if let Some(r) = out.records.last_mut() {
            r.split = Some("test".into());
        }
    }
    let dir = ctx.out.join("predictions").join("embed").join(&scene);
    std::fs::create_dir_all(&dir)?;
    write_predictions(&dir.join(format!("{method}.safetensors")), &data, &predicted)?;
    Ok(out)
}

/// [`score_model`] on the validation windows.
pub(super) fn score_validation(
    ctx: &EvalContext,
    model_dir: &Path,
    scene: &str,
    method: &str,
    data: &EmbedData,
    model: &EmbedModel,
) -> crate::Result<ExperimentOutput> {
    let (scores, parts) = validation_breakdown(data, model)?;
    let frames = validation_frames(data)?;
    let truth: Vec<Vec<f64>> = frames
        .iter()
        .map(|f| data.dataset.sequences[f.sequence].frame(f.frame).to_vec())
        .collect();
    let floor = mean_force_residual(data, &truth)?;
    let mut out = ExperimentOutput::new("embed", ctx.size);
    out.notes.push(format!(
        "embed score: {} ({method}) on the {} validation windows of {}",
        model_dir.display(),
        data.validation_windows.len(),
        scene
    ));
    let scale = data.phys_scale(model.config.phys_scale);
    out.notes.push(format!(
        "physics scale s = {scale:.4e} m/N ({:?})",
        model.config.phys_scale
    ));
    let mut record = |method: &str, metric: &str, value: f64, unit: &str| {
        out.record(scene, method, metric, value, unit, Timing::default());
        if let Some(r) = out.records.last_mut() {
            r.split = Some("validation".into());
        }
    };
    record(method, "m-rms", scores.m_rms, "mm");
    // How hard PB-loss pulls at this model (the weight the λ_ephys grid centres on).
    if let Some(parity) = ephys_parity(data.num_vertices(), scores, scale) {
        record(method, "ephys-parity", parity, "1");
    }
    for (who, r) in [(method, parts), ("ground-truth", floor)] {
        record(who, "m-phys", r.total, "N^2");
        record(who, "m-phys-inertial", r.inertial, "N^2");
        record(who, "m-phys-potential", r.potential, "N^2");
    }
    Ok(out)
}

/// The linear baselines of a scene: PCA on the frames the embedding trains on
/// ([`data::pca_training_frames`]) with the autoencoder's latent size, scored on the test
/// frames as `pca`, and the same latent MLP on the PCA codes (issue 31's baseline for
/// simulation), every seed, in Table IV as `pca + MLP`. Returns PCA's retrieval nDCG and
/// the components it kept.
pub(super) fn pca_baselines(s: &Scene, r: &mut SceneResults) -> crate::Result<(f64, usize)> {
    let (data, scene) = (&s.data, s.name);
    let pca = PositionPca::fit(&data::pca_training_frames(data), r.config.autoencoder.latent)?;
    // The seeds train at once ([`EvalContext::concurrently`]); each returns its roll-out
    // scores and its long roll-out.
    let pca_runs = s
        .ctx
        .concurrently(s.seeds.len(), |k| pca_mlp(s, &r.config, &pca, s.seeds[k]))?;
    let (pca_rollouts, pca_long): (Vec<Scores>, Vec<Curve>) = pca_runs.into_iter().unzip();
    let out = &mut r.output;
    out.curves.extend(Curve::over_seeds(&pca_long)?);
    r.table_4.push((scene.into(), "pca + MLP".into(), pca_rollouts));
    let t = Instant::now();
    let predicted: Vec<Vec<f64>> = data
        .test_frames
        .iter()
        .map(|f| pca.decode(&pca.encode(data.dataset.sequences[f.sequence].frame(f.frame))))
        .collect();
    let seconds = t.elapsed().as_secs_f64() / predicted.len().max(1) as f64;
    tables::record_method(out, s, "pca", (&[], &[score(data, &predicted)?]), seconds);
    let to = s.ctx.out.join("predictions").join("embed").join(scene);
    std::fs::create_dir_all(&to)?;
    write_predictions(&to.join("pca.safetensors"), data, &predicted)?;
    let codes: Vec<Vec<f64>> = data
        .test_frames
        .iter()
        .map(|f| pca.encode(data.dataset.sequences[f.sequence].frame(f.frame)))
        .collect();
    Ok((full_ranking_ndcg(data, &codes)?, pca.num_components()))
}

/// The latent MLP on `pca`'s codes with `seed`, trained like stage 2 on the same windows
/// and selected on the same validation windows (a model of another configuration is
/// retrained): its Table IV roll-out scores and its long roll-out.
fn pca_mlp(s: &Scene, config: &EmbedTrainingSettings, pca: &PositionPca, seed: u64) -> crate::Result<(Scores, Curve)> {
    let pca_config = PcaSimulatorSettings {
        hidden: config.latent_hidden.clone(),
        adam: config.adam,
        batch: config.batch,
        epochs: config.epochs[1].max(1),
        seed,
        schedule: config.schedule,
    };
    let pca_dir = s.models.join("pca-mlp").join(format!("seed-{seed}"));
    let stored: Option<PcaSimulatorSettings> = std::fs::read_to_string(pca_dir.join("config.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok());
    if pca_dir.exists() && stored.as_ref() != Some(&pca_config) {
        std::fs::remove_dir_all(&pca_dir)?;
    }
    std::fs::create_dir_all(&pca_dir)?;
    weft_data::files::write_json(&pca_dir.join("config.json"), &pca_config)?;
    let label = format!("embed/{}/pca-mlp/seed-{seed}", s.name);
    let progress = crate::progress::TrainProgress::new(s.ctx.quiet, &label)?;
    let mut progress = progress.tagged(format!("pca-mlp/seed-{seed}"));
    let pca_sim = weft_nn::pca_simulator::train(&pca_dir, &s.data, pca.clone(), &pca_config, &mut progress)
        .with_context(|| format!("training {label}"))?;
    drop(progress);
    Ok((
        pca_rollout_scores(&s.data, &pca_sim)?,
        pca_long_rollout(s.name, &s.data, &pca_sim)?,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluate::embed::tests::simulated_sheet;
    use crate::evaluate::embed::*;
    use weft_nn::trainer::TrainingState;

    /// M_phys as documented: a frame whose grasped vertices miss the controls is scored
    /// with them at the controls. The simulated frame pins its grasp at `q_m`, so moving
    /// the grasp off `q_m` must leave M_phys where the solver's frame has it, while the
    /// residual at the frame's own grasped positions (the former metric) grows.
    #[test]
    fn m_phys_prescribes_the_grasp_to_the_controls() {
        let data = EmbedData::new(simulated_sheet(5, false)).unwrap();
        let seq = &data.dataset.sequences[0];
        let (p2, p1, p) = (seq.frame(2), seq.frame(3), seq.frame(4));
        let at = FrameRef { sequence: 0, frame: 4 };
        assert_eq!(data.dataset.with_grasp_at(p, seq.control(4)).unwrap(), p.to_vec());
        let mut off = p.to_vec();
        for &g in &data.dataset.grasp {
            off[3 * g] += 0.01;
            off[3 * g + 2] -= 0.005;
        }
        let solver = data.integrator.m_phys(p2, p1, p).unwrap();
        let scored = m_phys(&data, p2, p1, &off, at).unwrap();
        assert!(
            (scored - solver).abs() <= 1e-12 * solver.max(1e-30),
            "{scored} vs {solver}"
        );
        let unprescribed = data.integrator.m_phys(p2, p1, &off).unwrap();
        assert!(unprescribed > 1e3 * solver.max(1e-30), "{unprescribed} vs {solver}");
        // Controls of the wrong length are a typed error, not a panic.
        assert!(data.dataset.with_grasp_at(p, &seq.control(4)[1..]).is_err());
    }

    /// M_phys split into its forces: on the ground truth the inertial and potential forces
    /// cancel down to the solver's tolerance, and a model's split sums to the M_phys the
    /// λ_ephys choice reads.
    #[test]
    fn the_validation_breakdown_splits_m_phys_and_the_ground_truth_balances() {
        let data = EmbedData::new(simulated_sheet(20, false)).unwrap();
        let frames = validation_frames(&data).unwrap();
        let truth: Vec<Vec<f64>> = frames
            .iter()
            .map(|f| data.dataset.sequences[f.sequence].frame(f.frame).to_vec())
            .collect();
        let floor = mean_force_residual(&data, &truth).unwrap();
        assert!(floor.inertial > 0.0, "{floor:?}");
        assert!(floor.total < 1e-6 * floor.inertial, "{floor:?}");
        assert!(
            (floor.potential - floor.inertial).abs() < 1e-3 * floor.inertial,
            "{floor:?}"
        );
        let model = EmbedModel::new(training_config(Size::Quick), &data).unwrap();
        let (scores, parts) = validation_breakdown(&data, &model).unwrap();
        assert_eq!(scores, validation_scores(&data, &model).unwrap());
        assert_eq!(scores.m_phys, parts.total);
        // An untrained decoder is far from force balance: the residual is of the forces' size.
        assert!(parts.total > 1e3 * floor.total, "{parts:?} vs {floor:?}");
        // Squared parts of a sum: |a + b|² ≤ (|a| + |b|)².
        assert!(parts.total.sqrt() <= parts.inertial.sqrt() + parts.potential.sqrt() + 1e-9);
    }

    /// Every file of `dir` (recursively) that is not JSON: what a checkpoint of the run
    /// leaves behind (docs/EMBEDDING.md).
    fn weights(dir: &Path) -> Vec<std::path::PathBuf> {
        let mut out = Vec::new();
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                out.extend(weights(&p));
            } else if p.extension().and_then(|e| e.to_str()) != Some("json") {
                out.push(p);
            }
        }
        out
    }

    /// A model scored once keeps its scores beside it: a later run reads them back without
    /// the weights (a run carried to another machine by its JSON files) and trains
    /// nothing, and a model of another configuration is retrained and scored afresh.
    #[test]
    fn a_scored_model_is_read_back_without_its_weights_and_rescored_under_another_configuration() {
        let data = EmbedData::new(simulated_sheet(20, false)).unwrap();
        let root = std::env::temp_dir().join(format!("weft-embed-scores-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let ctx = EvalContext {
            quiet: true,
            ..EvalContext::new(Size::Quick, root.clone())
        };
        let dir = root.join("model");
        let config = EmbedTrainingSettings {
            epochs: [1, 1, 1],
            ..training_config(Size::Quick)
        };
        // `ball-ms` labels the model so that it draws the embedding scatter.
        let role = Role {
            scene: "ball-ms",
            method: "ours",
            first_seed: true,
        };
        let first = scored_model(&ctx, &data, &config, &dir, role).unwrap();
        let extras = first.first_seed.as_ref().unwrap();
        assert!(extras.scatter.is_some() && extras.ik.is_none());
        assert_eq!(first.long_rollout.as_ref().unwrap().method, "ours");
        assert!(first.stage_2_rollout.is_some());
        assert!(first.test.m_rms.is_finite() && first.test.m_rms > 0.0);
        assert!(dir.join(PREDICTIONS_FILE).exists());
        // Scores kept before every seed's long roll-out was: the roll-out is added from the
        // weights, the same curve; without the weights the scores are read as they are.
        let without = ModelScores {
            long_rollout: None,
            ..first.clone()
        };
        weft_nn::checkpoint::write_json(&dir.join(SCORES_FILE), &without).unwrap();
        let upgraded = scored_model(&ctx, &data, &config, &dir, role).unwrap();
        assert_eq!(upgraded.long_rollout, first.long_rollout);
        let kept: ModelScores = weft_nn::checkpoint::read_json(&dir.join(SCORES_FILE)).unwrap();
        assert_eq!(kept.long_rollout, first.long_rollout, "the added roll-out is kept");
        let weights_before = weights(&dir);
        for w in weights(&dir) {
            std::fs::remove_file(w).unwrap();
        }
        weft_nn::checkpoint::write_json(&dir.join(SCORES_FILE), &without).unwrap();
        let bare = scored_model(&ctx, &data, &config, &dir, role).unwrap();
        assert!(bare.long_rollout.is_none() && weights(&dir).is_empty());
        assert!(!weights_before.is_empty());
        weft_nn::checkpoint::write_json(&dir.join(SCORES_FILE), &first).unwrap();
        let again = scored_model(&ctx, &data, &config, &dir, role).unwrap();
        assert_eq!(
            serde_json::to_string(&again).unwrap(),
            serde_json::to_string(&first).unwrap()
        );
        assert!(weights(&dir).is_empty(), "nothing was trained again");
        let longer = EmbedTrainingSettings {
            epochs: [1, 1, 2],
            ..config.clone()
        };
        let other = scored_model(&ctx, &data, &longer, &dir, role).unwrap();
        assert_eq!(other.config, longer);
        assert!(!weights(&dir).is_empty(), "the other configuration was trained");
        let _ = std::fs::remove_dir_all(&root);
    }

    /// Models trained at once score exactly as each trained alone on a pool of the same
    /// size: a model's results depend on its share of the cores, never on what trains
    /// beside it.
    #[test]
    fn models_trained_at_once_score_as_each_trained_alone() {
        let data = EmbedData::new(simulated_sheet(20, false)).unwrap();
        let root = std::env::temp_dir().join(format!("weft-embed-jobs-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let ctx = |jobs| EvalContext {
            quiet: true,
            jobs,
            ..EvalContext::new(Size::Quick, root.clone())
        };
        let jobs = |under: &str| -> Vec<Job> {
            [(0, true, 0.5), (1, false, 0.0)]
                .into_iter()
                .map(|(seed, first_seed, ephys)| {
                    let mut config = EmbedTrainingSettings {
                        epochs: [1, 1, 1],
                        ..with_seed(&training_config(Size::Quick), seed)
                    };
                    config.weights.ephys = ephys;
                    let role = Role {
                        scene: "sheet-ms",
                        method: if ephys > 0.0 { "ours" } else { "no-pb" },
                        first_seed,
                    };
                    Job::new(config, root.join(under).join(format!("seed-{seed}")), role)
                })
                .collect()
        };
        let (together, alone) = (jobs("together"), jobs("alone"));
        let at_once = two.install(|| scored_models(&ctx(2), &data, &together)).unwrap();
        let one_by_one = one.install(|| scored_models(&ctx(1), &data, &alone)).unwrap();
        // Everything but the wall times.
        let figures = |s: &ModelScores| {
            serde_json::to_string(&(&s.config, s.validation, s.test, s.rollout, s.stage_2_rollout)).unwrap()
        };
        assert_eq!(at_once.len(), 2);
        for (a, b) in at_once.iter().zip(&one_by_one) {
            assert_eq!(figures(a), figures(b));
        }
        assert_ne!(figures(&at_once[0]), figures(&at_once[1]));
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn a_model_trained_under_another_configuration_is_stale_unless_only_unused_fields_differ() {
        let dir = std::env::temp_dir().join(format!("weft-embed-stale-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let (ours, baseline) = (dir.join("ours"), dir.join("no-pb"));
        std::fs::create_dir_all(&ours).unwrap();
        std::fs::create_dir_all(&baseline).unwrap();
        let config = training_config(Size::Quick);
        assert_eq!(config.phys_scale, weft_nn::embed::PhysScale::Curvature);
        assert!(!stale(&dir.join("nothing"), &config), "no model is not a stale model");
        // A configuration as stored before the field existed.
        let legacy = |c: &EmbedTrainingSettings| {
            let mut v = serde_json::to_value(c).unwrap();
            v.as_object_mut().unwrap().remove("phys_scale");
            v.to_string()
        };
        std::fs::write(ours.join("config.json"), legacy(&config)).unwrap();
        let mut zeroed = method_config(&config, true);
        zeroed.schedule.early_stopping_patience = Some(5);
        std::fs::write(baseline.join("config.json"), legacy(&zeroed)).unwrap();
        assert!(stale(&ours, &method_config(&config, false)));
        // The baseline never evaluates L_phys: its scale does not matter.
        assert!(!stale(&baseline, &zeroed));
        // More epochs or a longer patience train on; any other change means retraining.
        let mut more = zeroed.clone();
        more.epochs[2] += 1;
        more.schedule.early_stopping_patience = Some(20);
        assert!(!stale(&baseline, &more));
        // Unless a stage trained more epochs than asked: its kept weights may be beyond them.
        let stage_1 = weft_nn::embed::stage_dir(&baseline, 1);
        std::fs::create_dir_all(&stage_1).unwrap();
        let trained = TrainingState {
            config: zeroed.trainer(1),
            epochs_done: 3,
            initial_validation: 1.0,
            best_epoch: 3,
            best_validation: 0.5,
            lr_factor: 1.0,
            epochs_since_best: 0,
            stopped_early: false,
            history: Vec::new(),
        };
        std::fs::write(stage_1.join("training.json"), serde_json::to_string(&trained).unwrap()).unwrap();
        // Without its weights (a copy of the small files) the stage cannot be trained on.
        assert!(stale(&baseline, &more));
        for kind in ["last", "best"] {
            let group = stage_1.join(kind).join("autoencoder");
            std::fs::create_dir_all(&group).unwrap();
            for file in ["params.safetensors", "optimizer.safetensors", "state.json"] {
                std::fs::write(group.join(file), "").unwrap();
            }
        }
        assert!(!stale(&baseline, &more));
        let mut fewer = more.clone();
        fewer.epochs[0] = 2;
        assert!(stale(&baseline, &fewer));
        std::fs::remove_dir_all(&stage_1).unwrap();
        let mut reseeded = zeroed.clone();
        reseeded.seed += 1;
        assert!(stale(&baseline, &reseeded));
        let mut impatient = zeroed.clone();
        impatient.schedule.early_stopping_patience = Some(1);
        assert!(
            stale(&baseline, &impatient),
            "a shorter patience could have stopped earlier"
        );
        std::fs::write(baseline.join("config.json"), "not json").unwrap();
        assert!(stale(&baseline, &zeroed));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
