//! The guarded roll-out: a [`Surrogate`] proposes each frame of an implicit-Euler scene, and
//! a [`Guard`] checks the proposal against the step's own physics before passing it on
//! (docs/GUARD.md).
//!
//! Per frame: propose → evaluate the residual `∇E(x)` of the step's incremental potential
//! (Tan et al. Eq. 4, the integrator's own gradient) → bound the distance to the step's
//! minimiser ([`ErrorEstimate`]) → accept if the bound is within the tolerance `τ`, else
//! run the integrator's Newton solver **from the proposal** until it is. The next proposal
//! starts from the frame passed on, so the error the guard admits does not accumulate
//! through the surrogate's history. A non-finite or exploding proposal is never passed on:
//! it is rejected, counted, and the step is solved from the solver's own start.

mod estimate;
mod quasistatic;
mod soft_tissue;
mod surrogate;

use std::time::Instant;

use crate::error::{Error, Result};
use crate::integrators::ImplicitEuler;
use crate::scenes::MotionLabel;

use estimate::Estimator;
pub use estimate::{
    CERTIFICATE_ITERATIONS, ErrorEstimate, EstimatePreconditioner, LAGGED_FACTOR_ITERATIONS, NEWTON_ESTIMATE_ITERATIONS,
};
pub use quasistatic::{
    LoadStep, MODULUS_INVERSE_ITERATIONS, PreviousEquilibrium, QuasistaticEstimator, QuasistaticGuard,
    QuasistaticSurrogate,
};
pub use soft_tissue::{GuardedTissueFrame, InteriorCompletion, SkinningCompleted};
pub use surrogate::{InertialPredictor, StepInput, Surrogate, SurrogateError};

/// When a proposal is good enough to pass on.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GuardTolerance {
    /// The estimate ([`ErrorEstimate::mm`]), or the bound per
    /// [`GuardSettings::acceptance`], is at most `τ` millimetres (mass-weighted RMS per
    /// coordinate).
    Millimetres(f64),
    /// The ground truth's own test: the largest free-DOF residual force is within the
    /// integrator's Newton tolerance, so an accepted proposal is a converged step. The
    /// dial's accurate end.
    GroundTruth,
}

/// Which figure of the [`ErrorEstimate`] the tolerance judges.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Acceptance {
    /// The Newton-step estimate ([`ErrorEstimate::mm`], docs/GUARD.md Eq. G6): exact to
    /// first order in the distance, on every frame, but not a bound.
    #[default]
    Estimate,
    /// The certified bound ([`ErrorEstimate::bound_mm`], Eq. G3): a proposal is accepted
    /// only where the step's modulus is certified positive and the bound is within `τ`.
    /// A guarantee, and conservative by the step's condition number.
    CertifiedBound,
}

/// How far a rejected proposal is corrected.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Correction {
    /// Newton from the proposal until the guard's tolerance holds (the cheapest
    /// correction the tolerance admits).
    #[default]
    ToTolerance,
    /// Newton from the proposal to the integrator's own tolerance (the ground truth's
    /// frame, reached from a learned start).
    ToGroundTruth,
}

/// Settings of a [`Guard`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GuardSettings {
    pub tolerance: GuardTolerance,
    pub correction: Correction,
    /// Whether `τ` judges the Newton-step estimate or the certified bound.
    pub acceptance: Acceptance,
    /// A proposal that moves any coordinate farther than this multiple of the accepted
    /// frame's bounding-box diagonal in one step has exploded and is rejected.
    pub explosion_factor: f64,
    /// How the estimate's Newton-step solve is preconditioned.
    #[serde(default)]
    pub preconditioner: EstimatePreconditioner,
}

impl GuardSettings {
    /// Accept within `tolerance_mm` (mm); refused unless positive and finite.
    pub fn millimetres(tolerance_mm: f64) -> Result<Self> {
        let s = Self {
            tolerance: GuardTolerance::Millimetres(tolerance_mm),
            ..Self::ground_truth()
        };
        s.validate()?;
        Ok(s)
    }

    /// Accept only what the ground truth's own convergence test accepts; correct to it.
    pub fn ground_truth() -> Self {
        Self {
            tolerance: GuardTolerance::GroundTruth,
            correction: Correction::ToGroundTruth,
            acceptance: Acceptance::Estimate,
            explosion_factor: 1.0,
            preconditioner: EstimatePreconditioner::default(),
        }
    }

    /// Checks the tolerance (positive, finite) and the explosion factor.
    pub fn validate(&self) -> Result<()> {
        if let GuardTolerance::Millimetres(t) = self.tolerance {
            crate::error::check_positive("guard tolerance (mm)", t)?;
        }
        crate::error::check_positive("guard explosion factor", self.explosion_factor)
    }
}

/// Why a proposal was rejected without being judged by its estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rejection {
    /// A NaN or infinite coordinate.
    NonFinite,
    /// A coordinate moved farther than [`GuardSettings::explosion_factor`] allows.
    Exploded,
    /// Finite positions whose residual force is not (an inverted element, an overflow).
    NonFiniteResidual,
}

/// What the guard did with a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Outcome {
    /// The proposal was passed on as is.
    Accepted,
    /// The proposal's estimate exceeded the tolerance; Newton started from it.
    Corrected,
    /// The proposal was unusable; Newton started from the solver's own start.
    Rejected(Rejection),
}

/// A frame's true error against a reference frame.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TrueError {
    /// `1000 · ‖x − x_ref‖ / √(3V)`: M_rms of the frame (mm).
    pub m_rms_mm: f64,
    /// `1000 · ‖x − x_ref‖_M / √(3 Σ m)`: comparable with [`ErrorEstimate::mm`] (mm).
    pub mass_weighted_mm: f64,
}

/// Wall time of a guarded frame, split by who spent it (s).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct TimeSplit {
    /// The surrogate's `propose`.
    pub proposal: f64,
    /// The guard's checks and estimates.
    pub guard: f64,
    /// Newton solves of a corrected or rejected frame.
    pub correction: f64,
}

/// What one guarded frame did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GuardReport {
    pub frame: usize,
    pub outcome: Outcome,
    /// The estimate at the proposal (`None` when it was rejected before one was made).
    pub proposal_estimate: Option<ErrorEstimate>,
    /// The estimate at the frame passed on.
    pub estimate: ErrorEstimate,
    /// Newton iterations and numeric factorisations of the correction (0 if accepted).
    pub newton_iterations: usize,
    pub factorizations: usize,
    /// Numeric factorisations of the estimates' preconditioner in this frame.
    pub estimate_factorizations: usize,
    /// The proposal's and the passed-on frame's true errors, when a reference was given.
    pub proposal_error: Option<TrueError>,
    pub error: Option<TrueError>,
    pub seconds: TimeSplit,
}

/// Counts over a guarded roll-out.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct GuardTotals {
    pub frames: usize,
    pub accepted: usize,
    pub corrected: usize,
    pub rejected: usize,
    /// Frames passed on without a certified bound.
    pub unverified: usize,
    pub newton_iterations: usize,
    pub factorizations: usize,
    pub estimate_factorizations: usize,
}

/// One guarded frame of a cloth scene ([`crate::ClothSimulation::step_guarded`]).
#[derive(Debug, Clone)]
pub struct GuardedFrame {
    /// Flat positions `p_m` (m).
    pub positions: Vec<f64>,
    /// Prescribed grasp positions `q_m`, 3 per grasped vertex (m).
    pub controls: Vec<f64>,
    pub label: MotionLabel,
    pub report: GuardReport,
}

/// A surrogate stepped under a guard, for one implicit-Euler integrator's mesh.
#[derive(Debug)]
pub struct Guard {
    settings: GuardSettings,
    surrogate: Box<dyn Surrogate>,
    estimator: Estimator,
    totals: GuardTotals,
}

impl Guard {
    /// A guard of `surrogate` on `integrator`'s scene (named `scene`, `Δt` the
    /// integrator's). Refuses bad settings and a surrogate built for another mesh, scene
    /// or time step, naming the mismatch.
    pub fn new(
        integrator: &ImplicitEuler,
        scene: &str,
        surrogate: Box<dyn Surrogate>,
        settings: GuardSettings,
    ) -> Result<Self> {
        settings.validate()?;
        let mismatch = |what: &'static str, expected: String, got: String| Error::SurrogateMismatch {
            surrogate: surrogate.name().to_string(),
            what,
            expected,
            got,
        };
        let n = integrator.positions().len();
        if surrogate.num_dofs() != n {
            return Err(mismatch(
                "mesh DOF count",
                format!("{n} ({} vertices)", n / 3),
                format!("{} ({} vertices)", surrogate.num_dofs(), surrogate.num_dofs() / 3),
            ));
        }
        if let Some(s) = surrogate.scene() {
            if s != scene {
                return Err(mismatch("scene", scene.to_string(), s.to_string()));
            }
        }
        if let Some(dt) = surrogate.dt() {
            if (dt - integrator.dt()).abs() > 1e-9 * integrator.dt() {
                return Err(mismatch("time step (s)", integrator.dt().to_string(), dt.to_string()));
            }
        }
        Ok(Self {
            settings,
            estimator: Estimator::new(integrator, settings.preconditioner)?,
            surrogate,
            totals: GuardTotals::default(),
        })
    }

    pub fn settings(&self) -> &GuardSettings {
        &self.settings
    }
    pub fn surrogate(&self) -> &dyn Surrogate {
        self.surrogate.as_ref()
    }
    pub fn surrogate_mut(&mut self) -> &mut dyn Surrogate {
        self.surrogate.as_mut()
    }
    pub fn totals(&self) -> &GuardTotals {
        &self.totals
    }

    /// The estimate at `x` as the integrator's next frame (its history is the
    /// integrator's state), without stepping.
    pub fn estimate(&mut self, integrator: &ImplicitEuler, x: &[f64]) -> Result<ErrorEstimate> {
        self.check_length(x.len())?;
        self.estimator.estimate(integrator, x)
    }

    /// `‖a − b‖_M` over all DOFs (m·√kg), the norm the estimate bounds.
    pub fn mass_norm(&self, a: &[f64], b: &[f64]) -> f64 {
        self.estimator.m_norm(a, b)
    }

    fn check_length(&self, got: usize) -> Result<()> {
        let expected = self.surrogate.num_dofs();
        if got == expected {
            return Ok(());
        }
        Err(Error::SurrogateMismatch {
            surrogate: self.surrogate.name().to_string(),
            what: "proposal length (DOFs)",
            expected: expected.to_string(),
            got: got.to_string(),
        })
    }

    /// Advances `integrator` by frame `frame` with controls `prescribed` under the guard;
    /// `reference` is the ground truth's frame, if known, for the report's true errors.
    pub fn step(
        &mut self,
        integrator: &mut ImplicitEuler,
        frame: usize,
        prescribed: &[(usize, f64)],
        reference: Option<&[f64]>,
    ) -> Result<GuardReport> {
        crate::anchors::check_prescribed(prescribed, integrator.fixed())?;
        if let Some(r) = reference {
            self.check_length(r.len())?;
        }
        let mut seconds = TimeSplit::default();
        let clock = Instant::now();
        let input = StepInput {
            frame,
            dt: integrator.dt(),
            current: integrator.positions(),
            previous: integrator.previous_positions(),
            prescribed,
        };
        let mut x = self.surrogate.propose(&input).map_err(|source| Error::Surrogate {
            surrogate: self.surrogate.name().to_string(),
            source,
        })?;
        seconds.proposal = clock.elapsed().as_secs_f64();
        self.check_length(x.len())?;
        let clock = Instant::now();
        let proposal_error = reference.map(|r| self.true_error(&x, r));
        let (rejection, proposal_estimate) = self.screen(integrator, prescribed, &mut x)?;
        let accepted = rejection.is_none()
            && proposal_estimate
                .as_ref()
                .is_some_and(|e| self.acceptable(integrator, e));
        seconds.guard = clock.elapsed().as_secs_f64();
        let mut report = GuardReport {
            frame,
            outcome: Outcome::Accepted,
            proposal_estimate,
            estimate: proposal_estimate.unwrap_or_else(Estimator::non_finite),
            newton_iterations: 0,
            factorizations: 0,
            estimate_factorizations: proposal_estimate.map_or(0, |e| e.factorizations),
            proposal_error,
            error: None,
            seconds,
        };
        if !accepted {
            report.outcome = rejection.map_or(Outcome::Corrected, Outcome::Rejected);
            if rejection.is_some() {
                x = integrator.inertial_start(prescribed)?;
            }
            self.correct(integrator, prescribed, &mut x, &mut report)?;
        }
        integrator.advance_to(&x)?;
        self.surrogate.observe(&x, !accepted);
        report.error = reference.map(|r| self.true_error(&x, r));
        self.count(&report);
        Ok(report)
    }

    /// Rejects an unusable proposal, else sets its fixed DOFs to the step's constraints
    /// and estimates its error.
    fn screen(
        &mut self,
        integrator: &ImplicitEuler,
        prescribed: &[(usize, f64)],
        x: &mut [f64],
    ) -> Result<(Option<Rejection>, Option<ErrorEstimate>)> {
        if x.iter().any(|v| !v.is_finite()) {
            return Ok((Some(Rejection::NonFinite), None));
        }
        let current = integrator.positions();
        let limit = self.settings.explosion_factor * bounding_box_diagonal(current).max(f64::MIN_POSITIVE);
        if weft_linalg::max_abs(x.iter().zip(current).map(|(a, b)| a - b)) > limit {
            return Ok((Some(Rejection::Exploded), None));
        }
        integrator.constrain(prescribed, x);
        let estimate = self.estimator.estimate(integrator, x)?;
        if !estimate.residual_m_inv.is_finite() {
            return Ok((Some(Rejection::NonFiniteResidual), None));
        }
        Ok((None, Some(estimate)))
    }

    /// Whether `estimate` passes the guard's tolerance.
    fn acceptable(&self, integrator: &ImplicitEuler, estimate: &ErrorEstimate) -> bool {
        match self.settings.tolerance {
            GuardTolerance::Millimetres(tau) => match self.settings.acceptance {
                Acceptance::Estimate => estimate.mm <= tau,
                Acceptance::CertifiedBound => estimate.bound_mm.is_some_and(|b| b <= tau),
            },
            GuardTolerance::GroundTruth => estimate.residual_max <= integrator.settings.tolerance,
        }
    }

    /// Newton from `x` until the guard's tolerance holds (or to the ground truth's, per
    /// [`GuardSettings::correction`]); `x` ends at the frame to pass on.
    fn correct(
        &mut self,
        integrator: &mut ImplicitEuler,
        prescribed: &[(usize, f64)],
        x: &mut [f64],
        report: &mut GuardReport,
    ) -> Result<()> {
        let ground_truth = integrator.settings;
        let mut settings = ground_truth;
        if let (GuardTolerance::Millimetres(tau), Correction::ToTolerance) =
            (self.settings.tolerance, self.settings.correction)
        {
            // ‖g‖_{M⁻¹} ≤ ‖g‖_∞ √(Σ 1/m_i), so this residual force meets τ at the
            // proposal's modulus (docs/GUARD.md, Eq. G5); never tighter than the truth's.
            let modulus = match report.proposal_estimate {
                Some(e) if e.certified => e.modulus,
                _ => 1.0 / integrator.dt().powi(2),
            };
            let force = self
                .estimator
                .max_residual_for(modulus * self.estimator.distance_of_mm(tau));
            settings.tolerance = force.max(ground_truth.tolerance);
        }
        for attempt in [settings, ground_truth] {
            let clock = Instant::now();
            let newton = integrator.solve_step_from(prescribed, x, &attempt)?;
            report.seconds.correction += clock.elapsed().as_secs_f64();
            report.newton_iterations += newton.iterations;
            report.factorizations += newton.factorizations;
            let clock = Instant::now();
            report.estimate = self.estimator.estimate(integrator, x)?;
            report.estimate_factorizations += report.estimate.factorizations;
            report.seconds.guard += clock.elapsed().as_secs_f64();
            // The modulus at the solution may be below the proposal's: then the loose
            // solve did not meet τ, and the second attempt solves to the truth's tolerance.
            if attempt == ground_truth || self.acceptable(integrator, &report.estimate) {
                break;
            }
        }
        Ok(())
    }

    fn true_error(&self, x: &[f64], reference: &[f64]) -> TrueError {
        let sq: f64 = x.iter().zip(reference).map(|(a, b)| (a - b).powi(2)).sum();
        TrueError {
            m_rms_mm: 1e3 * (sq / x.len().max(1) as f64).sqrt(),
            mass_weighted_mm: self.estimator.to_mm(self.estimator.m_norm(x, reference)),
        }
    }

    fn count(&mut self, report: &GuardReport) {
        count_into(&mut self.totals, report);
    }
}

/// Adds a guarded frame's report to a roll-out's totals.
fn count_into(t: &mut GuardTotals, report: &GuardReport) {
    t.frames += 1;
    match report.outcome {
        Outcome::Accepted => t.accepted += 1,
        Outcome::Corrected => t.corrected += 1,
        Outcome::Rejected(_) => t.rejected += 1,
    }
    t.unverified += usize::from(!report.estimate.certified);
    t.newton_iterations += report.newton_iterations;
    t.factorizations += report.factorizations;
    t.estimate_factorizations += report.estimate_factorizations;
}

/// The diagonal of the axis-aligned bounding box of flat positions (m).
fn bounding_box_diagonal(x: &[f64]) -> f64 {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in x.chunks_exact(3) {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt()
}
