//! The `guarded` experiment on `limb-jiggle` (volumetric: tet FEM, implicit Euler, six
//! substeps per frame; docs/GUARD.md, "limb-jiggle (volumetric)").
//!
//! The limb's surrogates are the inertial predictor (the whole state) and the limb
//! family's baseline, the skinned surface, with the interior nodes completed by the
//! harmonic extension `weft_sim::guard::InteriorCompletion` (`skinning-completed`). The
//! guard judges every implicit-Euler substep, so a surrogate proposes each substep's state;
//! the figures are per stored frame.
//!
//! 1. The held-out sequence: the built-in `limb-jiggle` scene (its own seed, not one of the
//!    dataset's) simulated by today's solver (`SoftTissue::step_frame`), timed.
//! 2. The estimate's honesty and each surrogate's one-step error: on every substep of the
//!    truth's history, the proposal against the truth's step (split `held-out`).
//! 3. The dial, as on `sheet-ms` (`super::guarded::dial`): M_rms over all nodes against the
//!    ground truth's frames, frames accepted, Newton iterations and wall time per frame.
//!    The `-truth-tolerance` rows against the `ground-truth` row are issue 73's target 1:
//!    Newton from the proposal against Newton from the solver's own start.

use std::sync::Arc;
use std::time::Instant;

use weft_data::Size;
use weft_sim::SoftTissueScene;
use weft_sim::guard::{Guard, GuardSettings, InertialPredictor, InteriorCompletion, SkinningCompleted, Surrogate};
use weft_sim::scenes::soft_tissue::SoftTissue;

use super::context::EvalContext;
use super::guarded::{Honesty, RolloutTally, dial, propose, rollout_header, write_frames};
use crate::records::{ExperimentOutput, Table, Timing};

const SCENE: &str = "limb-jiggle";

/// Frames of the held-out sequence: the altconv experiment's quick sequences' length at
/// quick size (`altconv::QUICK_FRAMES`, on the same quick limb), one second otherwise.
fn frames(size: Size) -> usize {
    match size {
        Size::Quick => 12,
        _ => 30,
    }
}

/// Today's solver's frames (all nodes) of the held-out sequence, the settled start first.
struct LimbTruth {
    frames: Vec<Vec<f64>>,
    seconds_per_frame: f64,
    iterations_per_frame: f64,
}

fn ground_truth(scene: &SoftTissueScene) -> crate::Result<LimbTruth> {
    let mut sim = scene.build()?;
    let mut frames = vec![sim.positions().to_vec()];
    let (clock, mut iterations) = (Instant::now(), 0);
    for _ in 0..scene.frames {
        let report = sim.step_frame()?;
        iterations += report.steps.iter().map(|s| s.newton.iterations).sum::<usize>();
        frames.push(sim.positions().to_vec());
    }
    let n = scene.frames.max(1) as f64;
    Ok(LimbTruth {
        frames,
        seconds_per_frame: clock.elapsed().as_secs_f64() / n,
        iterations_per_frame: iterations as f64 / n,
    })
}

/// The limb's surrogates, fresh for each roll-out (the completion's factor shared).
fn surrogates(sim: &SoftTissue, completion: &Arc<InteriorCompletion>) -> Vec<(&'static str, Box<dyn Surrogate>)> {
    vec![
        (
            "inertial",
            Box::new(InertialPredictor::for_integrator(sim.integrator())),
        ),
        (
            "skinning-completed",
            Box::new(SkinningCompleted::with_completion(sim, completion.clone())),
        ),
    ]
}

/// Adds the `limb-jiggle` rows, notes and table to the `guarded` experiment's output.
pub(super) fn run(ctx: &EvalContext, out: &mut ExperimentOutput) -> crate::Result<()> {
    let mut scene = SoftTissueScene::builtin_named(SCENE, ctx.size == Size::Quick);
    scene.frames = frames(ctx.size);
    let truth = ground_truth(&scene)?;
    let probe = scene.build()?;
    let clock = Instant::now();
    let completion = Arc::new(InteriorCompletion::for_tissue(&probe)?);
    let factor_seconds = clock.elapsed().as_secs_f64();
    out.notes.push(format!(
        "guarded: held-out roll-out of the built-in {SCENE} ({} nodes, {} surface vertices, {} frames of {} \
         implicit-Euler substeps); ground truth {:.4} s and {:.2} Newton iterations per frame; the interior \
         completion (harmonic, Eq. G8) factorised in {factor_seconds:.4} s; M_rms over all nodes",
        truth.frames[0].len() / 3,
        probe.surface().volume_vertex.len(),
        scene.frames,
        scene.params.substeps,
        truth.seconds_per_frame,
        truth.iterations_per_frame,
    ));
    out.record(
        SCENE,
        "ground-truth",
        "newton-iterations-per-frame",
        truth.iterations_per_frame,
        "count",
        Timing::new(truth.seconds_per_frame, truth.seconds_per_frame),
    );
    for (name, surrogate) in surrogates(&probe, &completion) {
        estimate_honesty(&scene, surrogate)?.record(out, SCENE, name);
    }
    let predictions = ctx.out.join("predictions").join("guarded").join(SCENE);
    let mut rows = Vec::new();
    for (setting, settings) in dial()? {
        for (name, surrogate) in surrogates(&probe, &completion) {
            let method = format!("{name}-{setting}");
            let tally = rollout(&scene, &truth, &method, surrogate, settings, &predictions)?;
            rows.push(tally.record(out));
        }
    }
    out.tables.push(Table {
        title: format!("Guarded roll-outs of {SCENE}"),
        caption: format!(
            "Each surrogate stepped under the guard (docs/GUARD.md, \"limb-jiggle\") on the held-out sequence, every \
             implicit-Euler substep judged; M_rms over all nodes against today's solver at its own tolerance (the \
             ground truth, {:.4} s and {:.2} Newton iterations per frame), substeps passed on without Newton, Newton \
             iterations per frame and the wall time per frame split into proposal, guard and correction.",
            truth.seconds_per_frame, truth.iterations_per_frame
        ),
        header: rollout_header(),
        rows,
    });
    Ok(())
}

/// Every substep of the truth's history: the surrogate's proposal against the truth's
/// step, which is solved here exactly as `ImplicitEuler::step` solves it.
fn estimate_honesty(scene: &SoftTissueScene, surrogate: Box<dyn Surrogate>) -> crate::Result<Honesty> {
    let mut sim = scene.build()?;
    let mut guard = Guard::new(sim.integrator(), SCENE, surrogate, GuardSettings::ground_truth())?;
    let mut honesty = Honesty::default();
    for _ in 0..scene.frames {
        sim.step_frame_with(|integrator, s, prescribed| {
            let x = propose(&mut guard, integrator, s, prescribed)?;
            let mut step = integrator.inertial_start(prescribed)?;
            let settings = integrator.settings;
            integrator.solve_step_from(prescribed, &mut step, &settings)?;
            honesty.add(&mut guard, integrator, &x, &step)?;
            integrator.advance_to(&step)
        })?;
    }
    Ok(honesty)
}

/// One roll-out of the dial (`settings` `None`: unguarded); writes its frames beside the
/// ground truth's.
fn rollout<'a>(
    scene: &SoftTissueScene,
    truth: &LimbTruth,
    method: &'a str,
    surrogate: Box<dyn Surrogate>,
    settings: Option<GuardSettings>,
    predictions: &std::path::Path,
) -> crate::Result<RolloutTally<'a>> {
    let mut sim = scene.build()?;
    // Unguarded: a tolerance no estimate exceeds, so every finite proposal passes on.
    let settings = match settings {
        Some(s) => s,
        None => GuardSettings::millimetres(f64::MAX)?,
    };
    let mut guard = Guard::new(sim.integrator(), SCENE, surrogate, settings)?;
    let (mut errors, mut split, mut positions) = (Vec::new(), [0.0f64; 3], Vec::new());
    for reference in &truth.frames[1..] {
        let f = sim.step_frame_guarded(&mut guard, Some(reference))?;
        let last = f.reports.last().and_then(|r| r.error);
        errors.push(last.map_or(f64::NAN, |e| e.m_rms_mm));
        for r in &f.reports {
            split[0] += r.seconds.proposal;
            split[1] += r.seconds.guard;
            split[2] += r.seconds.correction;
        }
        positions.extend_from_slice(sim.positions());
    }
    write_frames(predictions, method, &truth.frames, &positions)?;
    Ok(RolloutTally {
        scene: SCENE,
        method,
        errors,
        split,
        totals: *guard.totals(),
        frames: truth.frames.len() - 1,
        ground_truth_seconds: truth.seconds_per_frame,
    })
}
