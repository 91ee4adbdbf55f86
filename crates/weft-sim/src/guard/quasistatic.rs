//! The guard on a quasistatic scene (docs/GUARD.md, "Quasistatic scenes"): a load step's
//! equilibrium `min_x E(x) = Ψ(x) − fᵀx` ([`Quasistatic`]) proposed by a surrogate and
//! checked by the step's own residual `∇E(x) = ∇Ψ(x) − f` before it is passed on.
//!
//! There is no mass term, so the cloth's metric and certificate (Eqs. G3–G4, `1/Δt² − ρ`)
//! do not carry over: the estimate here is in the Euclidean norm (metres), the Newton step
//! is solved directly with a Cholesky factor of the projected stiffness `H⁺` (the fixed
//! DOFs eliminated), and the modulus `μ ≤ λ_min(H)` is certified by a Cholesky
//! factorisation of `H − μI` that succeeds (Sylvester's law of inertia), `μ` taken from a
//! few inverse iterations. At the dial's accurate end the guard reads the residual alone,
//! the ground truth's own test, for one gradient evaluation.

use std::sync::Arc;
use std::time::Instant;

use weft_linalg::{CholeskyFactor, CholeskySolver, SymmetricMatrix, SymmetricPattern};

use super::{
    Acceptance, Correction, ErrorEstimate, GuardReport, GuardSettings, GuardTolerance, GuardTotals, Outcome, Rejection,
    SurrogateError, TimeSplit, TrueError, bounding_box_diagonal,
};
use crate::energy::{Energy, checked_pairs};
use crate::error::{Error, Result};
use crate::integrators::Quasistatic;

/// Inverse iterations with the factor of `H⁺` behind the modulus's Rayleigh quotient
/// (docs/GUARD.md, Eq. Q3); the quotient is an upper bound on `λ_min(H)` after any number,
/// and the certificate checks a fraction of it.
pub const MODULUS_INVERSE_ITERATIONS: usize = 6;

/// The fractions of the Rayleigh quotient tried as the certified modulus, largest first:
/// the first whose shifted matrix `H − μI` factorises is kept.
const MODULUS_FRACTIONS: [f64; 3] = [0.5, 0.25, 0.125];

/// What a quasistatic surrogate sees when asked for load step `step`: the last
/// **accepted** equilibrium, the load it is in equilibrium with and the step's load.
#[derive(Debug, Clone, Copy)]
pub struct LoadStep<'a> {
    /// Index of the load step to propose (the first is 1).
    pub step: usize,
    /// The last accepted equilibrium, flat positions (m); the rest state before step 1.
    pub current: &'a [f64],
    /// The load `current` is in equilibrium with (N, flat); `None` for the unloaded body.
    pub current_load: Option<&'a [f64]>,
    /// The step's external forces `f` (N, flat).
    pub load: &'a [f64],
}

/// Anything that proposes a quasistatic equilibrium under a load: NNWarp and the linear
/// solves it corrects (weft-nn's `nnwarp::WarpSurrogate`), or the last equilibrium itself
/// ([`PreviousEquilibrium`], the solver's own start).
pub trait QuasistaticSurrogate: Send + std::fmt::Debug {
    /// Short name for reports and errors.
    fn name(&self) -> &str;
    /// The DOF count (3 per node) of the body the surrogate was built for.
    fn num_dofs(&self) -> usize;
    /// The proposed equilibrium (flat positions, m; `num_dofs` entries). Its fixed DOFs
    /// may be left anywhere: the guard holds them where the body is held.
    fn propose(&mut self, input: &LoadStep<'_>) -> Result<Vec<f64>, SurrogateError>;
    /// The equilibrium the guard passed on (`corrected`: a Newton solve's, not the
    /// proposal). Surrogates without state ignore it.
    fn observe(&mut self, _accepted: &[f64], _corrected: bool) {}
}

/// The trivial quasistatic surrogate: the last accepted equilibrium, unchanged — where
/// [`Quasistatic::solve_from`] starts its load ramp.
#[derive(Debug, Clone)]
pub struct PreviousEquilibrium {
    num_dofs: usize,
}

impl PreviousEquilibrium {
    pub fn new(num_dofs: usize) -> Self {
        Self { num_dofs }
    }
}

impl QuasistaticSurrogate for PreviousEquilibrium {
    fn name(&self) -> &str {
        "previous-equilibrium"
    }
    fn num_dofs(&self) -> usize {
        self.num_dofs
    }
    fn propose(&mut self, input: &LoadStep<'_>) -> Result<Vec<f64>, SurrogateError> {
        Ok(input.current.to_vec())
    }
}

/// The estimate of a quasistatic frame's distance from the load step's equilibrium
/// (docs/GUARD.md, Eqs. Q1–Q4), in the Euclidean norm. [`ErrorEstimate`]'s fields read
/// with the identity in place of the mass matrix: `residual_m_inv = ‖∇E(x)‖` (N),
/// `modulus` the certified `μ ≤ λ_min(H)` (N/m; `−∞` where none is), `distance` the
/// projected Newton step's length `‖(H⁺)⁻¹ ∇E(x)‖` (m), `mm` and `bound_mm` RMS per
/// coordinate over all nodes (mm).
#[derive(Debug)]
pub struct QuasistaticEstimator {
    fixed: Vec<bool>,
    /// `√(3V)`: the RMS's denominator over all nodes, fixed ones included, as M_rms.
    rms_scale: f64,
    /// `√(free DOFs)`: `‖g‖ ≤ ‖g‖_∞ · this`.
    max_to_norm: f64,
    exact: SymmetricMatrix,
    projected: SymmetricMatrix,
    shifted: SymmetricMatrix,
    solver: CholeskySolver,
    grad: Vec<f64>,
}

impl QuasistaticEstimator {
    /// The estimator of a body of `num_dofs` DOFs whose potential is `internal` and whose
    /// `fixed` DOFs are held (the [`Quasistatic`] solver's).
    pub fn new(num_dofs: usize, internal: &[&dyn Energy], fixed: Vec<bool>) -> Result<Self> {
        if fixed.len() != num_dofs {
            return Err(Error::LengthMismatch {
                what: "fixed-DOF mask",
                expected: num_dofs,
                got: fixed.len(),
            });
        }
        let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(
            num_dofs / 3,
            checked_pairs(num_dofs, internal)?,
        ));
        let free = fixed.iter().filter(|f| !**f).count();
        Ok(Self {
            fixed,
            rms_scale: (num_dofs.max(1) as f64).sqrt(),
            max_to_norm: (free as f64).sqrt(),
            exact: SymmetricMatrix::zeros(pattern.clone()),
            projected: SymmetricMatrix::zeros(pattern.clone()),
            shifted: SymmetricMatrix::zeros(pattern.clone()),
            solver: CholeskySolver::new(pattern)?,
            grad: vec![0.0; num_dofs],
        })
    }

    /// A distance (m) as an RMS per coordinate over all nodes (mm).
    pub fn to_mm(&self, distance: f64) -> f64 {
        1e3 * distance / self.rms_scale
    }

    /// The distance (m) of an RMS per coordinate of `mm`.
    pub fn distance_of_mm(&self, mm: f64) -> f64 {
        1e-3 * mm * self.rms_scale
    }

    /// The largest free-DOF residual force (N) that guarantees `‖∇E‖ ≤ bound`.
    pub fn max_residual_for(&self, bound: f64) -> f64 {
        bound / self.max_to_norm.max(f64::MIN_POSITIVE)
    }

    /// The estimate at `x` of the equilibrium under `load` (Eqs. Q1–Q4): the residual,
    /// the projected Newton step's length, and the certified modulus and bound.
    pub fn estimate(&mut self, internal: &[&dyn Energy], load: &[f64], x: &[f64]) -> Result<ErrorEstimate> {
        let residual_only = self.residual(internal, load, x)?;
        if !residual_only.residual_m_inv.is_finite() {
            return Ok(residual_only);
        }
        self.exact.set_zero();
        self.projected.set_zero();
        for t in internal {
            t.add_hessian(x, false, &mut self.exact);
            t.add_hessian(x, true, &mut self.projected);
        }
        let residual = residual_only.residual_m_inv;
        let mut factorizations = 0;
        let (distance, step) = self.projected_step(&mut factorizations);
        let modulus = match &step {
            Some(factor) => self.certified_modulus(factor, &mut factorizations),
            None => f64::NEG_INFINITY,
        };
        let certified = modulus > 0.0;
        Ok(ErrorEstimate {
            modulus,
            certified,
            bound_mm: certified.then(|| self.to_mm(residual / modulus)),
            distance,
            mm: self.to_mm(distance),
            projected: true,
            factorizations,
            ..residual_only
        })
    }

    /// The residual alone at `x` under `load` (`residual_m_inv` = `‖∇E(x)‖`, N, and its
    /// largest free entry): what the ground truth's own convergence test reads, for one
    /// gradient evaluation. The distance, modulus and bound are not computed (`NaN`,
    /// `−∞`, `None`).
    pub fn residual(&mut self, internal: &[&dyn Energy], load: &[f64], x: &[f64]) -> Result<ErrorEstimate> {
        for (name, len) in [("load", load.len()), ("positions", x.len())] {
            if len != self.grad.len() {
                return Err(Error::LengthMismatch {
                    what: name,
                    expected: self.grad.len(),
                    got: len,
                });
            }
        }
        crate::energy::total_gradient(internal, x, &mut self.grad);
        let (mut sq, mut max) = (0.0f64, 0.0f64);
        for ((g, f), fixed) in self.grad.iter_mut().zip(load).zip(&self.fixed) {
            *g = if *fixed { 0.0 } else { *g - f };
            sq += *g * *g;
            max = max.max(g.abs());
        }
        // NaN compares false: a non-finite gradient must not read as a zero residual.
        if !sq.is_finite() || self.grad.iter().any(|g| !g.is_finite()) {
            return Ok(super::Estimator::non_finite());
        }
        Ok(ErrorEstimate {
            residual_m_inv: sq.sqrt(),
            residual_max: max,
            modulus: f64::NEG_INFINITY,
            certified: false,
            bound_mm: None,
            distance: f64::NAN,
            mm: f64::NAN,
            projected: false,
            cg_iterations: 0,
            factorizations: 0,
        })
    }

    /// `‖δ‖` of `H⁺ δ = ∇E(x)` (Eq. Q2), solved with a fresh factor of the projected
    /// stiffness, and the factor; `∞` and none where it does not factorise (it is positive
    /// definite wherever the fixed DOFs pin every rigid motion, unless an entry is not
    /// finite).
    fn projected_step(&mut self, factorizations: &mut usize) -> (f64, Option<CholeskyFactor>) {
        self.projected.constrain_dofs(&self.fixed);
        *factorizations += 1;
        match self.solver.factorize(&self.projected) {
            Ok(factor) => {
                let mut step = self.grad.clone();
                factor.solve_in_place(&mut step);
                (step.iter().map(|d| d * d).sum::<f64>().sqrt(), Some(factor))
            }
            Err(_) => (f64::INFINITY, None),
        }
    }

    /// A certified lower bound `μ > 0` on `λ_min(H)` over the free DOFs (Eq. Q3), or
    /// `−∞` where none was found. Inverse iterations with the projected factor steer `v`
    /// towards the softest modes; the Rayleigh quotient `q = vᵀHv` of the exact `H` bounds
    /// `λ_min(H)` from above whatever `v` is, and the first of `q/2, q/4, q/8` for which
    /// `H − μI` factorises is a lower bound (Sylvester's law of inertia).
    fn certified_modulus(&mut self, projected: &CholeskyFactor, factorizations: &mut usize) -> f64 {
        let mut v: Vec<f64> = self.fixed.iter().map(|f| if *f { 0.0 } else { 1.0 }).collect();
        for _ in 0..MODULUS_INVERSE_ITERATIONS {
            projected.solve_in_place(&mut v);
            let norm = v.iter().map(|a| a * a).sum::<f64>().sqrt();
            if !(norm.is_finite() && norm > 0.0) {
                return f64::NEG_INFINITY;
            }
            v.iter_mut().for_each(|a| *a /= norm);
        }
        // `v` is zero on the fixed DOFs, so the unconstrained `H` gives the free block's
        // quotient.
        let mut hv = vec![0.0; v.len()];
        self.exact.mul_vec(&v, &mut hv);
        let quotient = v.iter().zip(&hv).map(|(a, b)| a * b).sum::<f64>();
        if !(quotient > 0.0) {
            return f64::NEG_INFINITY;
        }
        for fraction in MODULUS_FRACTIONS {
            let mu = fraction * quotient;
            // The shift applies to the free block only: fixed DOFs are eliminated after it.
            self.shifted.copy_values_from(&self.exact);
            self.shifted.add_diagonal(-mu);
            self.shifted.constrain_dofs(&self.fixed);
            *factorizations += 1;
            if self.solver.factorize(&self.shifted).is_ok() {
                return mu;
            }
        }
        f64::NEG_INFINITY
    }
}

/// A [`QuasistaticSurrogate`] stepped under a guard through a body's load steps.
#[derive(Debug)]
pub struct QuasistaticGuard {
    settings: GuardSettings,
    surrogate: Box<dyn QuasistaticSurrogate>,
    estimator: QuasistaticEstimator,
    /// The ground truth's solver: its settings and tolerance are the truth's.
    solver: Quasistatic,
    /// The truth's load increments from one load step to the next, for a rejected
    /// proposal (the solver's own path).
    load_steps: usize,
    totals: GuardTotals,
}

impl QuasistaticGuard {
    /// A guard of `surrogate` on the body of `solver` (the ground truth's, with its
    /// settings) whose potential is `internal`; a rejected proposal is solved as the truth
    /// solves, from the last equilibrium in `load_steps` increments. Refuses bad settings
    /// and a surrogate of another body, naming the mismatch.
    pub fn new(
        solver: Quasistatic,
        internal: &[&dyn Energy],
        load_steps: usize,
        surrogate: Box<dyn QuasistaticSurrogate>,
        settings: GuardSettings,
    ) -> Result<Self> {
        settings.validate()?;
        if load_steps == 0 {
            return Err(Error::InvalidParameter {
                name: "load steps",
                value: 0.0,
                reason: "must be at least 1",
            });
        }
        let n = solver.fixed().len();
        if surrogate.num_dofs() != n {
            return Err(Error::SurrogateMismatch {
                surrogate: surrogate.name().to_string(),
                what: "body DOF count",
                expected: format!("{n} ({} nodes)", n / 3),
                got: format!("{} ({} nodes)", surrogate.num_dofs(), surrogate.num_dofs() / 3),
            });
        }
        Ok(Self {
            settings,
            estimator: QuasistaticEstimator::new(n, internal, solver.fixed().to_vec())?,
            surrogate,
            solver,
            load_steps,
            totals: GuardTotals::default(),
        })
    }

    pub fn settings(&self) -> &GuardSettings {
        &self.settings
    }
    pub fn surrogate_mut(&mut self) -> &mut dyn QuasistaticSurrogate {
        self.surrogate.as_mut()
    }
    pub fn totals(&self) -> &GuardTotals {
        &self.totals
    }
    pub fn estimator_mut(&mut self) -> &mut QuasistaticEstimator {
        &mut self.estimator
    }

    /// The truth's residual tolerance under `load` (N): [`Quasistatic`]'s
    /// `relative_tolerance · max|f|`, or its Newton tolerance for the unloaded body.
    pub fn truth_tolerance(&self, load: &[f64]) -> f64 {
        let max_load = weft_linalg::max_abs(load.iter().copied());
        if max_load > 0.0 {
            self.solver.relative_tolerance * max_load
        } else {
            self.solver.settings.tolerance
        }
    }

    fn check_length(&self, what: &'static str, got: usize) -> Result<()> {
        let expected = self.estimator.grad.len();
        if got == expected {
            return Ok(());
        }
        Err(Error::SurrogateMismatch {
            surrogate: self.surrogate.name().to_string(),
            what,
            expected: expected.to_string(),
            got: got.to_string(),
        })
    }

    /// Load step `step`: `x` holds the last accepted equilibrium under `from` (`None`:
    /// unloaded) on entry and the frame passed on under `load` on exit. `reference` is
    /// the ground truth's equilibrium, if known, for the report's true errors.
    pub fn step(
        &mut self,
        internal: &[&dyn Energy],
        step: usize,
        from: Option<&[f64]>,
        load: &[f64],
        x: &mut [f64],
        reference: Option<&[f64]>,
    ) -> Result<GuardReport> {
        self.check_length("positions (DOFs)", x.len())?;
        self.check_length("load (DOFs)", load.len())?;
        if let Some(f) = from {
            self.check_length("starting load (DOFs)", f.len())?;
        }
        if let Some(r) = reference {
            self.check_length("reference (DOFs)", r.len())?;
        }
        let mut seconds = TimeSplit::default();
        let clock = Instant::now();
        let input = LoadStep {
            step,
            current: x,
            current_load: from,
            load,
        };
        let mut proposal = self.surrogate.propose(&input).map_err(|source| Error::Surrogate {
            surrogate: self.surrogate.name().to_string(),
            source,
        })?;
        seconds.proposal = clock.elapsed().as_secs_f64();
        self.check_length("proposal length (DOFs)", proposal.len())?;
        let clock = Instant::now();
        let proposal_error = reference.map(|r| self.true_error(&proposal, r));
        let (rejection, proposal_estimate) = self.screen(internal, load, x, &mut proposal)?;
        let accepted = rejection.is_none() && proposal_estimate.is_some_and(|e| self.acceptable(load, &e));
        seconds.guard = clock.elapsed().as_secs_f64();
        let mut report = GuardReport {
            frame: step,
            outcome: Outcome::Accepted,
            proposal_estimate,
            estimate: proposal_estimate.unwrap_or_else(super::Estimator::non_finite),
            newton_iterations: 0,
            factorizations: 0,
            estimate_factorizations: proposal_estimate.map_or(0, |e| e.factorizations),
            proposal_error,
            error: None,
            seconds,
        };
        if accepted {
            x.copy_from_slice(&proposal);
        } else {
            report.outcome = rejection.map_or(Outcome::Corrected, Outcome::Rejected);
            self.correct(internal, from, load, x, proposal, &mut report)?;
        }
        self.surrogate.observe(x, !accepted);
        report.error = reference.map(|r| self.true_error(x, r));
        self.count(&report);
        Ok(report)
    }

    /// Rejects an unusable proposal, else holds its fixed DOFs where `current` holds
    /// them and estimates its error.
    fn screen(
        &mut self,
        internal: &[&dyn Energy],
        load: &[f64],
        current: &[f64],
        x: &mut [f64],
    ) -> Result<(Option<Rejection>, Option<ErrorEstimate>)> {
        if x.iter().any(|v| !v.is_finite()) {
            return Ok((Some(Rejection::NonFinite), None));
        }
        let limit = self.settings.explosion_factor * bounding_box_diagonal(current).max(f64::MIN_POSITIVE);
        if weft_linalg::max_abs(x.iter().zip(current).map(|(a, b)| a - b)) > limit {
            return Ok((Some(Rejection::Exploded), None));
        }
        for ((v, c), fixed) in x.iter_mut().zip(current).zip(&self.estimator.fixed) {
            if *fixed {
                *v = *c;
            }
        }
        let estimate = self.judge(internal, load, x)?;
        if !estimate.residual_m_inv.is_finite() {
            return Ok((Some(Rejection::NonFiniteResidual), None));
        }
        Ok((None, Some(estimate)))
    }

    /// What the guard's tolerance reads at `x`: the residual alone at the truth's
    /// tolerance (its own convergence test), else the full estimate.
    fn judge(&mut self, internal: &[&dyn Energy], load: &[f64], x: &[f64]) -> Result<ErrorEstimate> {
        match self.settings.tolerance {
            GuardTolerance::GroundTruth => self.estimator.residual(internal, load, x),
            GuardTolerance::Millimetres(_) => self.estimator.estimate(internal, load, x),
        }
    }

    fn acceptable(&self, load: &[f64], estimate: &ErrorEstimate) -> bool {
        match self.settings.tolerance {
            GuardTolerance::Millimetres(tau) => match self.settings.acceptance {
                Acceptance::Estimate => estimate.mm <= tau,
                Acceptance::CertifiedBound => estimate.bound_mm.is_some_and(|b| b <= tau),
            },
            GuardTolerance::GroundTruth => estimate.residual_max <= self.truth_tolerance(load),
        }
    }

    /// The residual force (N) a correction from the proposal stops at (Eq. Q5): with a
    /// certified modulus, `μ τ / √(free DOFs)`, which meets `τ` by the bound; else the
    /// proposal's own ratio of estimate to largest residual force, halved for safety.
    /// Never tighter than the truth's.
    fn correction_tolerance(&self, load: &[f64], proposal: Option<&ErrorEstimate>) -> f64 {
        let truth = self.truth_tolerance(load);
        let (GuardTolerance::Millimetres(tau), Correction::ToTolerance) =
            (self.settings.tolerance, self.settings.correction)
        else {
            return truth;
        };
        let force = match proposal {
            Some(e) if e.certified => self
                .estimator
                .max_residual_for(e.modulus * self.estimator.distance_of_mm(tau)),
            Some(e) if e.mm.is_finite() && e.mm > 0.0 => 0.5 * e.residual_max * tau / e.mm,
            _ => truth,
        };
        force.max(truth)
    }

    /// Newton from the proposal under `load` to the correction's tolerance, then, if the
    /// guard's tolerance still fails, to the truth's; a rejected proposal, or one Newton
    /// cannot converge from, is solved from the last equilibrium `x` as the truth is.
    fn correct(
        &mut self,
        internal: &[&dyn Energy],
        from: Option<&[f64]>,
        load: &[f64],
        x: &mut [f64],
        mut proposal: Vec<f64>,
        report: &mut GuardReport,
    ) -> Result<()> {
        let relative = self.solver.relative_tolerance;
        let max_load = weft_linalg::max_abs(load.iter().copied());
        let mut from_proposal = matches!(report.outcome, Outcome::Corrected);
        let loose = self.correction_tolerance(load, report.proposal_estimate.as_ref());
        let truth = self.truth_tolerance(load);
        for tolerance in [loose, truth] {
            if !from_proposal {
                break;
            }
            if max_load > 0.0 {
                self.solver.relative_tolerance = tolerance / max_load;
            }
            let clock = Instant::now();
            // Halving an increment that is all at one load would retry the same solve.
            let subdivisions = std::mem::replace(&mut self.solver.max_subdivisions, 0);
            let solved = self.solver.solve_from(internal, Some(load), load, &mut proposal, 1);
            self.solver.relative_tolerance = relative;
            self.solver.max_subdivisions = subdivisions;
            report.seconds.correction += clock.elapsed().as_secs_f64();
            match solved {
                Ok(r) => self.tally(&r, report),
                // Newton could not converge from the proposal: the truth's own path.
                Err(Error::NotConverged { .. } | Error::NonFinite { .. } | Error::Linalg(_)) => {
                    from_proposal = false;
                    break;
                }
                Err(e) => return Err(e),
            }
            let clock = Instant::now();
            report.estimate = self.judge(internal, load, &proposal)?;
            report.estimate_factorizations += report.estimate.factorizations;
            report.seconds.guard += clock.elapsed().as_secs_f64();
            if tolerance <= truth || self.acceptable(load, &report.estimate) {
                break;
            }
        }
        if from_proposal {
            x.copy_from_slice(&proposal);
            return Ok(());
        }
        let clock = Instant::now();
        let r = self.solver.solve_from(internal, from, load, x, self.load_steps)?;
        report.seconds.correction += clock.elapsed().as_secs_f64();
        self.tally(&r, report);
        let clock = Instant::now();
        report.estimate = self.judge(internal, load, x)?;
        report.estimate_factorizations += report.estimate.factorizations;
        report.seconds.guard += clock.elapsed().as_secs_f64();
        Ok(())
    }

    fn tally(&self, r: &crate::QuasistaticReport, report: &mut GuardReport) {
        report.newton_iterations += r.newton.iter().map(|n| n.iterations).sum::<usize>();
        report.factorizations += r.newton.iter().map(|n| n.factorizations).sum::<usize>();
    }

    /// The Euclidean metric has no masses: both figures are M_rms.
    fn true_error(&self, x: &[f64], reference: &[f64]) -> TrueError {
        let sq: f64 = x.iter().zip(reference).map(|(a, b)| (a - b).powi(2)).sum();
        let mm = self.estimator.to_mm(sq.sqrt());
        TrueError {
            m_rms_mm: mm,
            mass_weighted_mm: mm,
        }
    }

    fn count(&mut self, report: &GuardReport) {
        super::count_into(&mut self.totals, report);
    }
}
