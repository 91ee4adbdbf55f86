//! The `guarded` experiment on the NNWarp beam (quasistatic, tet FEM; docs/GUARD.md,
//! "Quasistatic scenes").
//!
//! The body is the `nnwarp` experiment's training beam at the run's size, clamped at its
//! −x end, Neo-Hookean with that experiment's material, under its evaluation field. The
//! load grows in [`LOAD_STEPS`] equal steps until the linear answer moves some node by
//! [`LAST_LEVEL`] unit-sphere units (the largest load that experiment scores); each step's
//! ground truth is `Quasistatic::solve_from` the previous equilibrium, as that experiment's
//! reference is solved.
//!
//! 1. The surrogates: NNWarp (the committed Neo-Hookean model,
//!    `docs/results/models/nnwarp/neo-hookean`, or the `nnwarp` experiment's own in
//!    `OUT/nnwarp/models/`), modal warping, the stiffness-warped linear solve alone and the
//!    plain linear solve (weft-nn's `WarpSurrogate`), and the trivial one, the previous
//!    equilibrium (the solver's own start).
//! 2. Each one's one-step error and the estimate's honesty, one load step from the truth's
//!    equilibrium on every step (split `held-out`).
//! 3. The dial (`super::guarded::dial`): M_rms over all nodes against the truth's
//!    equilibria, steps accepted, Newton iterations and wall time per load step. The
//!    `-unguarded` rows run no guard at all: every proposal is passed on, and the time is
//!    the surrogate's alone.

use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::Vector3;
use weft_nn::nnwarp::{WarpProposal, WarpSurrogate, WarpSurrogateBody, load_model};
use weft_sim::energies::{ConstantForce, LameParameters, Material, TetElasticity};
use weft_sim::guard::{
    GuardSettings, LoadStep, PreviousEquilibrium, QuasistaticEstimator, QuasistaticGuard, QuasistaticSurrogate,
};
use weft_sim::warp::{FieldDirection, unit_sphere_normalization};
use weft_sim::{Energy, Quasistatic};

use super::context::EvalContext;
use super::guarded::{Honesty, RolloutTally, dial, rollout_header, write_frames};
use super::nnwarp::data::{beam_params, min_x_anchors};
use super::nnwarp::{
    DENSITY, FIELD_ANGLES, POISSON, REFERENCE_NEWTON_ITERATIONS, REFERENCE_STEPS, REFERENCE_SUBDIVISIONS, WARP_SOLVES,
    WARP_TOLERANCE, YOUNG,
};
use crate::error::Context;
use crate::records::{ExperimentOutput, Table, Timing};

const SCENE: &str = "beam/neo-hookean";

/// Load steps of the roll-out, equal in load.
const LOAD_STEPS: usize = 12;

/// The linear answer's largest node displacement at the last load (unit-sphere units):
/// the `nnwarp` experiment's largest level (`nnwarp::LEVELS`).
const LAST_LEVEL: f64 = 1.5;

/// The beam, its potential and its loads.
struct Beam {
    mesh: weft_mesh::TetMesh,
    anchors: Vec<usize>,
    elastic: TetElasticity,
    fixed: Vec<bool>,
    /// The load of each step (N, flat), growing.
    loads: Vec<Vec<f64>>,
    field: FieldDirection,
}

impl Beam {
    fn new(ctx: &EvalContext) -> crate::Result<Self> {
        let mesh = weft_mesh::generators::beam(&beam_params(ctx.size))?;
        let anchors = min_x_anchors(&mesh);
        let lame = LameParameters::from_young_poisson(YOUNG, POISSON)?;
        let elastic = TetElasticity::new(&mesh, Material::NeoHookean, lame)?;
        let fixed = weft_sim::anchors::fixed_dofs(mesh.num_vertices(), &anchors)?;
        let direction = weft_sim::energies::hemisphere_direction(FIELD_ANGLES.0, FIELD_ANGLES.1);
        let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), DENSITY);
        let unit = ConstantForce::directional(&masses, direction, 1.0)?.forces().to_vec();
        let mut beam = Self {
            field: FieldDirection::Directional(Vector3::from(direction)),
            mesh,
            anchors,
            elastic,
            fixed,
            loads: Vec::new(),
        };
        // The load whose linear answer reaches LAST_LEVEL, as the nnwarp experiment scales it.
        let reach = WarpSurrogate::new(&beam.body(), WarpProposal::Linear)?
            .displacement(&unit)?
            .chunks_exact(3)
            .map(|c| Vector3::new(c[0], c[1], c[2]).norm())
            .fold(0.0, f64::max);
        let (_, scale) = unit_sphere_normalization(beam.mesh.positions());
        crate::error::ensure!(reach > 0.0, "the field moves no node of the beam");
        let full = LAST_LEVEL / (reach * scale);
        beam.loads = (1..=LOAD_STEPS)
            .map(|k| unit.iter().map(|f| f * full * k as f64 / LOAD_STEPS as f64).collect())
            .collect();
        Ok(beam)
    }

    fn body(&self) -> WarpSurrogateBody<'_> {
        WarpSurrogateBody {
            mesh: &self.mesh,
            anchors: &self.anchors,
            young: YOUNG,
            poisson: POISSON,
            warp_tolerance: WARP_TOLERANCE,
            warp_solves: WARP_SOLVES,
        }
    }

    fn internal(&self) -> [&dyn Energy; 1] {
        [&self.elastic]
    }

    /// The ground truth's solver, with the `nnwarp` experiment's reference settings.
    fn solver(&self) -> crate::Result<Quasistatic> {
        let mut q = Quasistatic::new(3 * self.mesh.num_vertices(), &self.internal(), self.fixed.clone())?;
        q.settings.max_iterations = REFERENCE_NEWTON_ITERATIONS;
        q.max_subdivisions = REFERENCE_SUBDIVISIONS;
        Ok(q)
    }
}

/// The truth's equilibria, rest first, with their cost per load step.
struct BeamTruth {
    frames: Vec<Vec<f64>>,
    seconds_per_step: f64,
    iterations_per_step: f64,
}

fn ground_truth(beam: &Beam) -> crate::Result<BeamTruth> {
    let mut solver = beam.solver()?;
    let mut x = beam.mesh.flat_positions();
    let mut frames = vec![x.clone()];
    let (clock, mut iterations) = (Instant::now(), 0);
    for (k, load) in beam.loads.iter().enumerate() {
        let from = k.checked_sub(1).map(|j| beam.loads[j].as_slice());
        let r = solver
            .solve_from(&beam.internal(), from, load, &mut x, REFERENCE_STEPS)
            .with_context(|| format!("the beam's equilibrium at load step {}", k + 1))?;
        iterations += r.newton.iter().map(|n| n.iterations).sum::<usize>();
        frames.push(x.clone());
    }
    let n = LOAD_STEPS as f64;
    Ok(BeamTruth {
        frames,
        seconds_per_step: clock.elapsed().as_secs_f64() / n,
        iterations_per_step: iterations as f64 / n,
    })
}

/// The committed Neo-Hookean model, else the `nnwarp` experiment's in `OUT`; `None` if
/// neither exists.
fn nnwarp_model(ctx: &EvalContext) -> Option<PathBuf> {
    let committed = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/results/models/nnwarp/neo-hookean");
    if committed.join("config.json").is_file() {
        return Some(committed);
    }
    let trained = ctx.out.join("nnwarp").join("models").join("neo-hookean");
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(trained)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("config.json").is_file())
        .collect();
    dirs.sort();
    dirs.pop()
}

/// The beam's surrogates, fresh for each roll-out.
fn surrogates(beam: &Beam, model: Option<&Path>) -> crate::Result<Vec<Box<dyn QuasistaticSurrogate>>> {
    let mut out: Vec<Box<dyn QuasistaticSurrogate>> = Vec::new();
    if let Some(dir) = model {
        let (_, mlp) = load_model(dir)?;
        let proposal = WarpProposal::NnWarp {
            mlp: Box::new(mlp),
            field: beam.field,
        };
        out.push(Box::new(WarpSurrogate::new(&beam.body(), proposal)?));
    }
    for proposal in [
        WarpProposal::ModalWarping,
        WarpProposal::WarpedLinear,
        WarpProposal::Linear,
    ] {
        out.push(Box::new(WarpSurrogate::new(&beam.body(), proposal)?));
    }
    out.push(Box::new(PreviousEquilibrium::new(3 * beam.mesh.num_vertices())));
    Ok(out)
}

/// Adds the beam's rows, notes and table to the `guarded` experiment's output.
pub(super) fn run(ctx: &EvalContext, out: &mut ExperimentOutput) -> crate::Result<()> {
    let clock = Instant::now();
    let beam = Beam::new(ctx)?;
    let truth = ground_truth(&beam)?;
    let model = nnwarp_model(ctx);
    out.notes.push(format!(
        "guarded: the NNWarp beam ({} nodes, {} tets, Neo-Hookean, E = {YOUNG} Pa, ν = {POISSON}), {LOAD_STEPS} load \
         steps to a linear reach of {LAST_LEVEL} unit-sphere units; ground truth (Quasistatic, {REFERENCE_STEPS} \
         increments per step) {:.4} s and {:.2} Newton iterations per load step; NNWarp model: {}; M_rms over all \
         nodes, the estimate in the Euclidean norm",
        beam.mesh.num_vertices(),
        beam.mesh.num_tets(),
        truth.seconds_per_step,
        truth.iterations_per_step,
        model.as_ref().map_or_else(
            || "none found (no committed model, none in OUT/nnwarp/models): the nnwarp rows are skipped".into(),
            |p| p.display().to_string()
        ),
    ));
    out.record(
        SCENE,
        "ground-truth",
        "newton-iterations-per-frame",
        truth.iterations_per_step,
        "count",
        Timing::new(truth.seconds_per_step, truth.seconds_per_step),
    );
    for surrogate in surrogates(&beam, model.as_deref())? {
        let name = surrogate.name().to_string();
        estimate_honesty(&beam, &truth, surrogate)?.record(out, SCENE, &name);
    }
    let predictions = ctx.out.join("predictions").join("guarded").join(SCENE);
    let mut rows = Vec::new();
    for (setting, settings) in dial()? {
        for surrogate in surrogates(&beam, model.as_deref())? {
            let method = format!("{}-{setting}", surrogate.name());
            let tally = rollout(&beam, &truth, &method, surrogate, settings, &predictions)?;
            rows.push(tally.record(out));
        }
    }
    out.tables.push(Table {
        title: format!("Guarded roll-outs of the NNWarp beam ({SCENE}, quasistatic)"),
        caption: format!(
            "Each surrogate's proposal of every load step judged by the quasistatic guard (docs/GUARD.md, \
             \"Quasistatic scenes\"); M_rms over all nodes against Quasistatic's equilibria at its own tolerance (the \
             ground truth, {:.4} s and {:.2} Newton iterations per load step), steps passed on without Newton, Newton \
             iterations per step and the wall time per step split into proposal, guard and correction.",
            truth.seconds_per_step, truth.iterations_per_step
        ),
        header: rollout_header(),
        rows,
    });
    out.notes.push(format!(
        "guarded: the NNWarp beam's rows took {:.1} s",
        clock.elapsed().as_secs_f64()
    ));
    Ok(())
}

/// The surrogate's proposal of load step `k + 1` from the equilibrium `current` under the
/// previous step's load.
fn propose(
    beam: &Beam,
    surrogate: &mut dyn QuasistaticSurrogate,
    k: usize,
    current: &[f64],
) -> weft_sim::Result<Vec<f64>> {
    let input = LoadStep {
        step: k + 1,
        current,
        current_load: k.checked_sub(1).map(|j| beam.loads[j].as_slice()),
        load: &beam.loads[k],
    };
    surrogate.propose(&input).map_err(|source| weft_sim::Error::Surrogate {
        surrogate: format!("{} (load step {})", surrogate.name(), k + 1),
        source,
    })
}

/// Every load step from the truth's previous equilibrium: the surrogate's proposal, its
/// estimate against its distance from the truth's equilibrium.
fn estimate_honesty(
    beam: &Beam,
    truth: &BeamTruth,
    mut surrogate: Box<dyn QuasistaticSurrogate>,
) -> crate::Result<Honesty> {
    let n = 3 * beam.mesh.num_vertices();
    let mut estimator = QuasistaticEstimator::new(n, &beam.internal(), beam.fixed.clone())?;
    let mut honesty = Honesty::default();
    for (k, load) in beam.loads.iter().enumerate() {
        let current = &truth.frames[k];
        let mut x = propose(beam, surrogate.as_mut(), k, current)?;
        // Held where the body is held, as the guard holds it.
        for ((v, c), fixed) in x.iter_mut().zip(current).zip(&beam.fixed) {
            if *fixed {
                *v = *c;
            }
        }
        let e = estimator.estimate(&beam.internal(), load, &x)?;
        let at_truth = estimator.estimate(&beam.internal(), load, &truth.frames[k + 1])?;
        let d = x
            .iter()
            .zip(&truth.frames[k + 1])
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        honesty.add_estimates(&e, &at_truth, d, &x, &truth.frames[k + 1]);
    }
    Ok(honesty)
}

/// One roll-out of the dial (`settings` `None`: unguarded); writes its equilibria beside
/// the truth's.
fn rollout<'a>(
    beam: &Beam,
    truth: &BeamTruth,
    method: &'a str,
    surrogate: Box<dyn QuasistaticSurrogate>,
    settings: Option<GuardSettings>,
    predictions: &Path,
) -> crate::Result<RolloutTally<'a>> {
    let Some(settings) = settings else {
        return unguarded(beam, truth, method, surrogate, predictions);
    };
    let mut guard = QuasistaticGuard::new(beam.solver()?, &beam.internal(), REFERENCE_STEPS, surrogate, settings)?;
    let mut x = beam.mesh.flat_positions();
    let (mut errors, mut split, mut positions) = (Vec::new(), [0.0f64; 3], Vec::new());
    for (k, load) in beam.loads.iter().enumerate() {
        let from = k.checked_sub(1).map(|j| beam.loads[j].as_slice());
        let r = guard.step(&beam.internal(), k + 1, from, load, &mut x, Some(&truth.frames[k + 1]))?;
        errors.push(r.error.map_or(f64::NAN, |e| e.m_rms_mm));
        split[0] += r.seconds.proposal;
        split[1] += r.seconds.guard;
        split[2] += r.seconds.correction;
        positions.extend_from_slice(&x);
    }
    write_frames(predictions, method, &truth.frames, &positions)?;
    Ok(RolloutTally {
        scene: SCENE,
        method,
        errors,
        split,
        totals: *guard.totals(),
        frames: LOAD_STEPS,
        ground_truth_seconds: truth.seconds_per_step,
    })
}

/// Every proposal passed on with no guard run: the surrogate's own speed and error.
fn unguarded<'a>(
    beam: &Beam,
    truth: &BeamTruth,
    method: &'a str,
    mut surrogate: Box<dyn QuasistaticSurrogate>,
    predictions: &Path,
) -> crate::Result<RolloutTally<'a>> {
    let mut x = beam.mesh.flat_positions();
    let (mut errors, mut seconds, mut positions) = (Vec::new(), 0.0, Vec::new());
    for k in 0..LOAD_STEPS {
        let clock = Instant::now();
        let next = propose(beam, surrogate.as_mut(), k, &x)?;
        seconds += clock.elapsed().as_secs_f64();
        x = next;
        surrogate.observe(&x, false);
        let sq: f64 = x.iter().zip(&truth.frames[k + 1]).map(|(a, b)| (a - b).powi(2)).sum();
        errors.push(1e3 * (sq / x.len() as f64).sqrt());
        positions.extend_from_slice(&x);
    }
    write_frames(predictions, method, &truth.frames, &positions)?;
    Ok(RolloutTally {
        scene: SCENE,
        method,
        errors,
        split: [seconds, 0.0, 0.0],
        totals: weft_sim::GuardTotals {
            frames: LOAD_STEPS,
            accepted: LOAD_STEPS,
            unverified: LOAD_STEPS,
            ..Default::default()
        },
        frames: LOAD_STEPS,
        ground_truth_seconds: truth.seconds_per_step,
    })
}
