//! The guard on a quasistatic tet beam (docs/GUARD.md, "Quasistatic scenes"): the
//! estimate against a dense Newton step and a dense eigen-decomposition, the bound where
//! certified, the dial's ends and typed errors.

use nalgebra::{DMatrix, DVector};
use weft_linalg::SymmetricMatrix;
use weft_sim::energies::{ConstantForce, LameParameters, Material, TetElasticity};
use weft_sim::guard::{
    GuardSettings, LoadStep, Outcome, PreviousEquilibrium, QuasistaticEstimator, QuasistaticGuard,
    QuasistaticSurrogate, SurrogateError,
};
use weft_sim::rng::SplitMix64;
use weft_sim::{Energy, Error, Quasistatic};
use weft_testkit::assert_close;

/// Load increments of the truth from one load step to the next.
const RAMP: usize = 4;

/// A 4 × 2 × 2-cell Neo-Hookean beam (1 × 0.5 × 0.5 m), clamped at x = 0, and the
/// directional load of `acceleration` m/s² on its lumped masses.
struct Beam {
    rest: Vec<f64>,
    fixed: Vec<bool>,
    elastic: TetElasticity,
    unit: Vec<f64>,
}

impl Beam {
    fn new() -> Self {
        let mesh = weft_mesh::generators::beam(&weft_mesh::generators::BeamParams {
            cells: [4, 2, 2],
            size: [1.0, 0.5, 0.5],
        })
        .unwrap();
        let lame = LameParameters::from_young_poisson(1e5, 0.3).unwrap();
        let elastic = TetElasticity::new(&mesh, Material::NeoHookean, lame).unwrap();
        let anchors: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&i| mesh.positions()[i].x.abs() < 1e-9)
            .collect();
        let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), 1000.0);
        let unit = ConstantForce::directional(&masses, [0.3, -1.0, 0.2], 1.0)
            .unwrap()
            .forces()
            .to_vec();
        Self {
            rest: mesh.flat_positions(),
            fixed: weft_sim::anchors::fixed_dofs(mesh.num_vertices(), &anchors).unwrap(),
            elastic,
            unit,
        }
    }

    fn internal(&self) -> [&dyn Energy; 1] {
        [&self.elastic]
    }

    fn load(&self, acceleration: f64) -> Vec<f64> {
        self.unit.iter().map(|f| f * acceleration).collect()
    }

    fn solver(&self) -> Quasistatic {
        Quasistatic::new(self.rest.len(), &self.internal(), self.fixed.clone()).unwrap()
    }

    /// The truth's equilibria under each of `accelerations`, each continued from the last.
    fn truth(&self, accelerations: &[f64]) -> Vec<Vec<f64>> {
        let mut solver = self.solver();
        let (mut x, mut from) = (self.rest.clone(), None::<Vec<f64>>);
        accelerations
            .iter()
            .map(|&a| {
                let load = self.load(a);
                solver
                    .solve_from(&self.internal(), from.as_deref(), &load, &mut x, RAMP)
                    .unwrap();
                from = Some(load);
                x.clone()
            })
            .collect()
    }

    fn perturbed(&self, x: &[f64], mm: f64, seed: u64) -> Vec<f64> {
        perturbed(&self.rest, &self.fixed, x, mm, seed)
    }
}

/// `x` plus smooth noise of RMS `mm` on the free DOFs: a random smooth field of the rest
/// positions, so the error is of the kind a surrogate makes.
fn perturbed(rest: &[f64], fixed: &[bool], x: &[f64], mm: f64, seed: u64) -> Vec<f64> {
    let mut rng = SplitMix64::new(seed);
    let a: Vec<f64> = (0..12).map(|_| rng.uniform(-0.5, 0.5)).collect();
    let mut d: Vec<f64> = (0..x.len())
        .map(|i| {
            let (v, k) = (i / 3, i % 3);
            let p = &rest[3 * v..3 * v + 3];
            if fixed[i] {
                0.0
            } else {
                a[4 * k] + a[4 * k + 1] * p[0] + a[4 * k + 2] * p[1] + a[4 * k + 3] * p[2] * p[0]
            }
        })
        .collect();
    let rms = (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt();
    d.iter_mut().for_each(|v| *v *= 1e-3 * mm / rms);
    x.iter().zip(&d).map(|(a, b)| a + b).collect()
}

fn m_rms_mm(a: &[f64], b: &[f64]) -> f64 {
    1e3 * (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

/// The free block of an assembled Hessian, dense.
fn dense_free(beam: &Beam, x: &[f64], project: bool) -> (DMatrix<f64>, Vec<usize>) {
    let free: Vec<usize> = (0..x.len()).filter(|&i| !beam.fixed[i]).collect();
    let pattern = std::sync::Arc::new(weft_linalg::SymmetricPattern::from_vertex_pairs(x.len() / 3, {
        let mut p = Vec::new();
        beam.elastic.hessian_pairs(&mut p);
        p
    }));
    let mut h = SymmetricMatrix::zeros(pattern.clone());
    beam.elastic.add_hessian(x, project, &mut h);
    let mut index = vec![usize::MAX; x.len()];
    free.iter().enumerate().for_each(|(k, &i)| index[i] = k);
    let mut dense = DMatrix::zeros(free.len(), free.len());
    for (slot, r, c) in pattern.entries() {
        if let (k, l) = (index[r], index[c])
            && k != usize::MAX
            && l != usize::MAX
        {
            dense[(k, l)] = h.values()[slot];
            dense[(l, k)] = h.values()[slot];
        }
    }
    (dense, free)
}

#[test]
fn the_estimate_is_the_dense_projected_newton_step_and_the_modulus_is_below_the_smallest_eigenvalue() {
    let beam = Beam::new();
    let truth = beam.truth(&[1.0, 3.0]);
    let load = beam.load(3.0);
    let mut estimator = QuasistaticEstimator::new(beam.rest.len(), &beam.internal(), beam.fixed.clone()).unwrap();
    for (mm, seed) in [(0.1, 1), (1.0, 2), (10.0, 3)] {
        let x = beam.perturbed(&truth[1], mm, seed);
        let e = estimator.estimate(&beam.internal(), &load, &x).unwrap();
        let (h_plus, free) = dense_free(&beam, &x, true);
        let mut g = vec![0.0; x.len()];
        weft_sim::energy::total_gradient(&beam.internal(), &x, &mut g);
        let g = DVector::from_iterator(free.len(), free.iter().map(|&i| g[i] - load[i]));
        let step = h_plus.clone().cholesky().unwrap().solve(&g);
        assert_close!(e.distance, step.norm(), rtol = 1e-8, atol = 0.0);
        assert_close!(e.residual_m_inv, g.norm(), rtol = 1e-10, atol = 0.0);
        // Near the equilibrium the Newton step is the distance to first order.
        let d = 1e-3 * mm * (x.len() as f64).sqrt();
        assert_close!(e.distance, d, rtol = 0.05 + 0.01 * mm, atol = 0.0);
        let (h, _) = dense_free(&beam, &x, false);
        let lambda_min = h.symmetric_eigenvalues().min();
        assert!(e.certified, "{mm} mm: not certified (λ_min {lambda_min})");
        assert!(
            e.modulus <= lambda_min && e.modulus >= lambda_min / 16.0,
            "{mm} mm: certified modulus {} against λ_min {lambda_min}",
            e.modulus
        );
    }
}

#[test]
fn the_bound_holds_wherever_it_is_certified() {
    let beam = Beam::new();
    let accelerations = [1.0, 2.0, 4.0, 6.0];
    let truth = beam.truth(&accelerations);
    let mut estimator = QuasistaticEstimator::new(beam.rest.len(), &beam.internal(), beam.fixed.clone()).unwrap();
    let mut certified = 0;
    for (k, (&a, x_star)) in accelerations.iter().zip(&truth).enumerate() {
        let load = beam.load(a);
        let at_truth = estimator.estimate(&beam.internal(), &load, x_star).unwrap();
        for (j, mm) in [0.01, 0.1, 1.0, 10.0, 30.0].into_iter().enumerate() {
            let x = beam.perturbed(x_star, mm, (10 * k + j) as u64);
            let e = estimator.estimate(&beam.internal(), &load, &x).unwrap();
            if let (Some(bound), Some(slack)) = (e.bound_mm, at_truth.bound_mm) {
                certified += 1;
                // The truth is the equilibrium only to its tolerance: its own bound covers that.
                let distance = m_rms_mm(&x, x_star);
                assert!(
                    distance <= bound + slack,
                    "load {a}, {mm} mm: distance {distance} mm above the bound {bound} + {slack} mm"
                );
            }
        }
    }
    assert!(certified >= 16, "only {certified} of 20 proposals certified");
}

/// Proposes the next reference equilibrium plus smooth noise of RMS `mm`.
#[derive(Debug)]
struct Noisy {
    frames: Vec<Vec<f64>>,
    mm: f64,
    rest: Vec<f64>,
    fixed: Vec<bool>,
    next: usize,
}

impl QuasistaticSurrogate for Noisy {
    fn name(&self) -> &str {
        "noisy"
    }
    fn num_dofs(&self) -> usize {
        self.rest.len()
    }
    fn propose(&mut self, _: &LoadStep<'_>) -> Result<Vec<f64>, SurrogateError> {
        let x = perturbed(
            &self.rest,
            &self.fixed,
            &self.frames[self.next],
            self.mm,
            self.next as u64 + 7,
        );
        self.next += 1;
        Ok(x)
    }
}

/// Proposes a NaN.
#[derive(Debug)]
struct Broken(usize);

impl QuasistaticSurrogate for Broken {
    fn name(&self) -> &str {
        "broken"
    }
    fn num_dofs(&self) -> usize {
        self.0
    }
    fn propose(&mut self, input: &LoadStep<'_>) -> Result<Vec<f64>, SurrogateError> {
        Ok(vec![f64::NAN; input.current.len()])
    }
}

/// Steps `surrogate` under `settings` through `accelerations`; the frames passed on and
/// the outcomes.
fn guarded(
    beam: &Beam,
    surrogate: Box<dyn QuasistaticSurrogate>,
    settings: GuardSettings,
    accelerations: &[f64],
    truth: &[Vec<f64>],
) -> (Vec<Vec<f64>>, Vec<Outcome>) {
    let mut guard = QuasistaticGuard::new(beam.solver(), &beam.internal(), RAMP, surrogate, settings).unwrap();
    let (mut x, mut from) = (beam.rest.clone(), None::<Vec<f64>>);
    let (mut frames, mut outcomes) = (Vec::new(), Vec::new());
    for (s, (&a, reference)) in accelerations.iter().zip(truth).enumerate() {
        let load = beam.load(a);
        let r = guard
            .step(&beam.internal(), s + 1, from.as_deref(), &load, &mut x, Some(reference))
            .unwrap();
        outcomes.push(r.outcome);
        frames.push(x.clone());
        from = Some(load);
    }
    (frames, outcomes)
}

#[test]
fn at_the_truth_tolerance_the_guarded_frames_are_the_quasistatic_solves() {
    let beam = Beam::new();
    let accelerations = [1.0, 2.0, 3.0];
    let truth = beam.truth(&accelerations);
    // A rejected proposal is solved along the truth's own path: the same frames, bit for bit.
    let n = beam.rest.len();
    let (frames, outcomes) = guarded(
        &beam,
        Box::new(Broken(n)),
        GuardSettings::ground_truth(),
        &accelerations,
        &truth,
    );
    assert!(outcomes.iter().all(|o| matches!(o, Outcome::Rejected(_))));
    assert_eq!(frames, truth);
    // Newton from the previous equilibrium or a noisy one reaches the truth's equilibrium
    // within what the truth's own tolerance admits.
    let mut estimator = QuasistaticEstimator::new(n, &beam.internal(), beam.fixed.clone()).unwrap();
    let surrogates: Vec<Box<dyn QuasistaticSurrogate>> = vec![
        Box::new(PreviousEquilibrium::new(n)),
        Box::new(Noisy {
            frames: truth.clone(),
            mm: 5.0,
            rest: beam.rest.clone(),
            fixed: beam.fixed.clone(),
            next: 0,
        }),
    ];
    for surrogate in surrogates {
        let (frames, outcomes) = guarded(&beam, surrogate, GuardSettings::ground_truth(), &accelerations, &truth);
        assert!(outcomes.iter().all(|o| *o == Outcome::Corrected), "{outcomes:?}");
        for ((f, t), &a) in frames.iter().zip(&truth).zip(&accelerations) {
            let load = beam.load(a);
            let mut slack = |x: &[f64]| {
                estimator
                    .estimate(&beam.internal(), &load, x)
                    .unwrap()
                    .bound_mm
                    .unwrap()
            };
            let (d, bound) = (m_rms_mm(f, t), slack(f) + slack(t));
            assert!(
                d <= bound && d < 1e-3,
                "load {a}: {d} mm from the truth (bound {bound} mm)"
            );
        }
    }
}

#[test]
fn a_perturbed_proposal_is_corrected_and_the_equilibrium_accepted() {
    let beam = Beam::new();
    let accelerations = [1.0, 2.0, 3.0];
    let truth = beam.truth(&accelerations);
    let noisy = |mm| Noisy {
        frames: truth.clone(),
        mm,
        rest: beam.rest.clone(),
        fixed: beam.fixed.clone(),
        next: 0,
    };
    let tau = 0.1;
    let (frames, outcomes) = guarded(
        &beam,
        Box::new(noisy(2.0)),
        GuardSettings::millimetres(tau).unwrap(),
        &accelerations,
        &truth,
    );
    assert!(outcomes.iter().all(|o| *o == Outcome::Corrected), "{outcomes:?}");
    for (f, t) in frames.iter().zip(&truth) {
        let d = m_rms_mm(f, t);
        assert!(d <= tau, "corrected frame {d} mm from the truth (τ = {tau} mm)");
    }
    let (frames, outcomes) = guarded(
        &beam,
        Box::new(noisy(1e-6)),
        GuardSettings::millimetres(tau).unwrap(),
        &accelerations,
        &truth,
    );
    assert!(outcomes.iter().all(|o| *o == Outcome::Accepted), "{outcomes:?}");
    assert!(frames.iter().zip(&truth).all(|(f, t)| m_rms_mm(f, t) < 1e-5));
}

#[test]
fn bad_input_is_refused_with_the_mismatch_named() {
    let beam = Beam::new();
    let n = beam.rest.len();
    let new = |s: Box<dyn QuasistaticSurrogate>, settings, steps| {
        QuasistaticGuard::new(beam.solver(), &beam.internal(), steps, s, settings)
    };
    let e = new(
        Box::new(PreviousEquilibrium::new(n + 3)),
        GuardSettings::ground_truth(),
        RAMP,
    )
    .unwrap_err();
    assert!(
        matches!(
            &e,
            Error::SurrogateMismatch {
                what: "body DOF count",
                ..
            }
        ),
        "{e}"
    );
    for tau in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(GuardSettings::millimetres(tau).is_err(), "τ = {tau} accepted");
    }
    let e = new(Box::new(PreviousEquilibrium::new(n)), GuardSettings::ground_truth(), 0).unwrap_err();
    assert!(matches!(e, Error::InvalidParameter { name: "load steps", .. }), "{e}");
    let mut guard = new(
        Box::new(PreviousEquilibrium::new(n)),
        GuardSettings::ground_truth(),
        RAMP,
    )
    .unwrap();
    let mut x = beam.rest.clone();
    let e = guard
        .step(&beam.internal(), 1, None, &beam.load(1.0)[3..], &mut x, None)
        .unwrap_err();
    assert!(
        matches!(
            &e,
            Error::SurrogateMismatch {
                what: "load (DOFs)",
                ..
            }
        ),
        "{e}"
    );
    let e = guard
        .step(
            &beam.internal(),
            1,
            None,
            &beam.load(1.0),
            &mut x,
            Some(&beam.rest[3..]),
        )
        .unwrap_err();
    assert!(
        matches!(
            &e,
            Error::SurrogateMismatch {
                what: "reference (DOFs)",
                ..
            }
        ),
        "{e}"
    );
}
