//! The guarded roll-out on the soft-tissue limb (`limb-jiggle`, tet FEM, implicit Euler;
//! docs/GUARD.md, "limb-jiggle (volumetric)").

use std::sync::Arc;

use nalgebra::{Matrix3, Rotation3, Vector3};
use weft_sim::SoftTissueScene;
use weft_sim::guard::{
    Guard, GuardSettings, InertialPredictor, InteriorCompletion, Outcome, SkinningCompleted, StepInput, Surrogate,
    SurrogateError,
};
use weft_sim::rng::SplitMix64;
use weft_sim::scenes::soft_tissue::SoftTissue;

const FRAMES: usize = 3;

fn jiggle() -> SoftTissue {
    let mut scene = SoftTissueScene::builtin_named("limb-jiggle", true);
    scene.params.seed = 11;
    scene.build().unwrap()
}

/// Every substep's state of `step_frame`'s frames (all nodes), the settled start first.
fn truth_substeps() -> Vec<Vec<f64>> {
    let mut sim = jiggle();
    let mut states = vec![sim.positions().to_vec()];
    for _ in 0..FRAMES {
        let steps = sim
            .step_frame_with(|integrator, _, prescribed| {
                integrator.step(prescribed)?;
                Ok(integrator.positions().to_vec())
            })
            .unwrap();
        states.extend(steps);
    }
    states
}

fn m_rms_mm(a: &[f64], b: &[f64]) -> f64 {
    1e3 * (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

#[test]
fn guarded_limb_at_the_truth_tolerance_reproduces_step_frame() {
    let mut reference = jiggle();
    let mut truth = Vec::new();
    for _ in 0..FRAMES {
        reference.step_frame().unwrap();
        truth.push(reference.positions().to_vec());
    }
    let tissue = jiggle();
    let surrogates: Vec<Box<dyn Surrogate>> = vec![
        Box::new(InertialPredictor::for_integrator(tissue.integrator())),
        Box::new(SkinningCompleted::new(&tissue).unwrap()),
    ];
    for surrogate in surrogates {
        let name = surrogate.name().to_string();
        let mut sim = jiggle();
        let mut guard = Guard::new(
            sim.integrator(),
            "limb-jiggle",
            surrogate,
            GuardSettings::ground_truth(),
        )
        .unwrap();
        for (m, frame) in truth.iter().enumerate() {
            let f = sim.step_frame_guarded(&mut guard, Some(frame)).unwrap();
            assert_eq!(f.reports.len(), sim.params().substeps);
            let tol = sim.integrator().settings.tolerance;
            assert!(f.reports.iter().all(|r| r.estimate.residual_max <= tol));
            let error = f.reports.last().unwrap().error.unwrap().m_rms_mm;
            if name == "inertial" {
                // The solver's own start: the same Newton solve, bit for bit.
                assert_eq!(sim.positions(), &frame[..], "{name}, frame {}", m + 1);
            } else {
                // Another start, the same minimiser to the truth's tolerance: microns, where
                // the skinned proposals are millimetres off.
                let proposal = f.reports[0].proposal_error.map_or(0.0, |e| e.m_rms_mm);
                assert!(
                    error < 1e-3,
                    "{name}, frame {}: {error} mm (proposal {proposal} mm)",
                    m + 1
                );
            }
        }
        assert_eq!(guard.totals().frames, FRAMES * sim.params().substeps);
    }
}

#[test]
fn interior_completion_reproduces_an_affine_map_of_the_rest_mesh() {
    let tissue = jiggle();
    let completion = InteriorCompletion::for_tissue(&tissue).unwrap();
    let rest = tissue.limb().mesh.positions();
    // A rotation, a shear-stretch and a translation: harmonic, so its interior is exact.
    let r = Rotation3::from_euler_angles(0.3, -0.5, 0.8);
    let a = r.matrix() * Matrix3::new(1.1, 0.2, 0.0, 0.0, 0.9, -0.1, 0.05, 0.0, 1.2);
    let b = Vector3::new(0.1, -0.2, 0.3);
    let exact: Vec<f64> = rest.iter().flat_map(|p| (a * p + b).as_slice().to_vec()).collect();
    let mut x = exact.clone();
    let held: Vec<usize> = tissue
        .surface()
        .volume_vertex
        .iter()
        .copied()
        .chain(tissue.limb().all_bone_nodes())
        .collect();
    let mut is_held = vec![false; rest.len()];
    for &v in &held {
        is_held[v] = true;
    }
    let interior: Vec<usize> = (0..rest.len()).filter(|&v| !is_held[v]).collect();
    assert!(!interior.is_empty(), "the quick limb has interior nodes");
    for &v in &interior {
        x[3 * v..3 * v + 3].copy_from_slice(&[7.0, -3.0, 5.0]);
    }
    completion.complete(&mut x);
    for (i, (got, want)) in x.iter().zip(&exact).enumerate() {
        assert!((got - want).abs() <= 1e-12, "DOF {i}: {got} against {want}");
    }
    // The same completion of a non-affine map moves the interior off it: the check above
    // can fail.
    let bent: Vec<f64> = rest.iter().flat_map(|p| [p.x, p.y + 0.5 * p.x * p.x, p.z]).collect();
    let mut y = bent.clone();
    completion.complete(&mut y);
    assert!(m_rms_mm(&y, &bent) > 1e-3);
}

/// Proposes the truth's substep state plus seeded noise of `noise_mm` on free DOFs.
#[derive(Debug)]
struct Oracle {
    states: Vec<Vec<f64>>,
    fixed: Vec<bool>,
    noise_mm: f64,
    rng: SplitMix64,
}

impl Surrogate for Oracle {
    fn name(&self) -> &str {
        "oracle"
    }
    fn num_dofs(&self) -> usize {
        self.states[0].len()
    }
    fn propose(&mut self, input: &StepInput<'_>) -> Result<Vec<f64>, SurrogateError> {
        let a = 1e-3 * self.noise_mm * 3f64.sqrt();
        Ok(self.states[input.frame]
            .iter()
            .zip(&self.fixed)
            .map(|(v, f)| if *f { *v } else { v + a * (2.0 * self.rng.unit() - 1.0) })
            .collect())
    }
}

#[test]
fn limb_guard_accepts_the_true_step_and_corrects_a_perturbed_one() {
    let states = truth_substeps();
    for (noise, expected) in [(0.0, Outcome::Accepted), (0.5, Outcome::Corrected)] {
        let mut sim = jiggle();
        let oracle = Oracle {
            states: states.clone(),
            fixed: sim.integrator().fixed().to_vec(),
            noise_mm: noise,
            rng: SplitMix64::new(73),
        };
        let mut guard = Guard::new(
            sim.integrator(),
            "limb-jiggle",
            Box::new(oracle),
            GuardSettings::ground_truth(),
        )
        .unwrap();
        for _ in 0..FRAMES {
            let f = sim.step_frame_guarded(&mut guard, None).unwrap();
            for r in &f.reports {
                assert_eq!(r.outcome, expected, "noise {noise} mm, step {}", r.frame);
                if expected == Outcome::Corrected {
                    assert!(r.newton_iterations > 0);
                    assert!(r.proposal_estimate.unwrap().mm > 0.1 * noise);
                }
            }
        }
        let last = states.last().unwrap();
        assert!(m_rms_mm(sim.positions(), last) < 1e-3, "noise {noise} mm");
    }
}

#[test]
fn limb_estimate_ranks_proposals_by_their_true_distance() {
    let states = truth_substeps();
    let mut sim = jiggle();
    let completion = Arc::new(InteriorCompletion::for_tissue(&sim).unwrap());
    let mut surrogates: Vec<Box<dyn Surrogate>> = vec![
        Box::new(InertialPredictor::for_integrator(sim.integrator())),
        Box::new(SkinningCompleted::with_completion(&sim, completion)),
    ];
    let probe: Box<dyn Surrogate> = Box::new(InertialPredictor::for_integrator(sim.integrator()));
    let mut guard = Guard::new(sim.integrator(), "limb-jiggle", probe, GuardSettings::ground_truth()).unwrap();
    let (mut estimates, mut distances) = (Vec::new(), Vec::new());
    for _ in 0..FRAMES {
        sim.step_frame_with(|integrator, s, prescribed| {
            for surrogate in surrogates.iter_mut() {
                let input = StepInput {
                    frame: s,
                    dt: integrator.dt(),
                    current: integrator.positions(),
                    previous: integrator.previous_positions(),
                    prescribed,
                };
                let mut x = surrogate.propose(&input).unwrap();
                integrator.constrain(prescribed, &mut x);
                estimates.push(guard.estimate(integrator, &x)?.distance);
                distances.push(guard.mass_norm(&x, &states[s]));
            }
            integrator.step(prescribed)
        })
        .unwrap();
    }
    let rho = weft_linalg::rank_correlation(&estimates, &distances);
    assert!(
        rho >= 0.9,
        "rank correlation {rho}: {estimates:?} against {distances:?}"
    );
    for (e, d) in estimates.iter().zip(&distances) {
        assert!(e / d > 0.5 && e / d < 2.0, "estimate {e} against distance {d}");
    }
}
