//! Newton's method with SPD projection, a descent-guaranteeing line search and a reused
//! symbolic Cholesky factorisation — the one nonlinear solver of weft — or, as the
//! alternative globalisation, a trust region on the exact Hessian solved by
//! preconditioned conjugate gradients (`trust_region`).

mod trust_region;

use std::sync::Arc;
use std::time::{Duration, Instant};

use weft_linalg::{CholeskySolver, SymmetricMatrix, SymmetricPattern};

use crate::energy::{Energy, total_gradient, total_value};
use crate::error::{Error, Result};

/// Armijo steps shorter than this fraction of the Newton step are not trusted: steps are
/// then judged by their residual force instead (see [`NewtonSolver::minimize`]).
const MIN_TRUSTED_STEP: f64 = 1e-6;

/// The residual force's round-off floor in units of `ε · max H_ii · max |x|` (see
/// [`NewtonSolver::minimize`]).
const ROUNDOFF_FLOOR_FACTOR: f64 = 64.0;

/// Settings of [`NewtonSolver`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NewtonSettings {
    /// Converged when the largest free-DOF residual force `|∂E/∂x_i|` is at most this (N).
    pub tolerance: f64,
    pub max_iterations: usize,
    /// Armijo sufficient-decrease constant.
    pub armijo: f64,
    /// Halvings of the step before the line search gives up.
    pub max_line_search: usize,
    /// When to project element Hessians to PSD (needed whenever an energy is non-convex).
    pub projection: HessianProjection,
    /// Reuse a factorisation for the next step while it keeps contracting the residual
    /// force: after a fresh Newton step that cut the residual at least
    /// [`REUSE_AFTER_FRESH`]-fold, and after a reused step that cut it at least
    /// [`REUSE_AFTER_REUSED`]-fold, both with a full step. Near a minimiser Newton
    /// converges quadratically and the Hessian barely changes, so such chord steps
    /// (Shamanskii's method) cost one solve instead of one factorisation. Off by default.
    pub reuse_factorization: bool,
    /// How steps are kept safe away from the minimiser.
    pub globalization: Globalization,
    /// When a minimisation does not converge, start it once more from the same point with
    /// the other strategy: shifting the exact Hessian ([`HessianProjection::Never`])
    /// leaves saddles fast but can wander in a crumpling sheet, projecting
    /// ([`HessianProjection::WhenIndefinite`]) is steady there but slow to leave a
    /// saddle, and where one fails the other often converges (docs/CLOTH.md,
    /// "Definiteness"). A trust region is retried with the line search and the
    /// configured projection; [`HessianProjection::Always`] has no other strategy. The
    /// report says which was used ([`NewtonReport::fallback`]). On by default; written
    /// into a scene file only when off.
    #[serde(skip_serializing_if = "is_true")]
    pub retry_other_strategy: bool,
    /// With [`HessianProjection::WhenIndefinite`] and the line search: after this many
    /// consecutive projected-Hessian iterations in which the residual force **rose**, the
    /// rest of the minimisation steps with the shifted exact Hessian
    /// ([`HessianProjection::Never`]). A rising residual while the energy falls is the
    /// iterate sliding down a direction of negative curvature that the projected matrix
    /// has clamped to zero: projected Newton then takes gradient-sized steps along it
    /// (dozens to hundreds of iterations), while the shifted exact Hessian follows it
    /// (docs/CLOTH.md, "Definiteness"). The report records the iteration
    /// ([`NewtonReport::exact_from_iteration`]). `None` (the default) never switches;
    /// written into a scene file only when set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exact_hessian_after_rises: Option<usize>,
    /// Inexact Newton: stop after this many iterations and accept the iterate, whatever
    /// its residual ([`NewtonReport::stopped_at_budget`] says so). Each accepted step has
    /// lowered the energy (the line search), so an implicit-Euler step stays stable; one
    /// iteration with per-element projected Hessians is Baraff & Witkin's linearised
    /// implicit Euler (SIGGRAPH 1998, §5). The answer is then no longer the minimiser to
    /// the tolerance but a cheaper approximation of it, whose error a user measures against
    /// a converged reference (docs/CLOTH.md, "Inexact steps"). `None` (the default)
    /// iterates to the tolerance; written into a scene file only when set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iteration_budget: Option<usize>,
    /// With the line search: at most this many fresh numeric factorisations per
    /// minimisation; once they are spent, every further iteration solves with the last
    /// factor (chord steps, Ortega & Rheinboldt's simplified Newton). A kept factor is
    /// of a positive definite matrix, so its direction is still one of descent and the
    /// line search still lowers the energy at every step, but convergence is linear,
    /// not quadratic. Paired with [`Self::iteration_budget`] it makes inexact steps that
    /// cost one factorisation and a few solves (docs/CLOTH.md, "Inexact steps"). A
    /// switch to the exact Hessian ([`Self::exact_hessian_after_rises`]) after the budget
    /// is spent keeps the factor. Not used by the trust region. `None` (the default):
    /// no limit; written into a scene file only when set.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub factorization_budget: Option<usize>,
}

fn is_true(v: &bool) -> bool {
    *v
}

/// How Newton keeps its steps safe where the quadratic model is poor (saddles, folds,
/// large steps).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Globalization {
    /// A backtracking line search along `−H⁻¹g`, `H` made positive definite per
    /// [`NewtonSettings::projection`] (one or more numeric factorisations per iteration).
    #[default]
    LineSearch,
    /// A trust region on the **exact** Hessian, its subproblem solved by Steihaug–Toint
    /// conjugate gradients preconditioned with a Cholesky factor of the element-projected
    /// (positive semi-definite) Hessian that is kept across iterations and calls while it
    /// serves (Conn, Gould & Toint, *Trust-Region Methods*, Alg. 7.5.1; Nocedal & Wright,
    /// Alg. 7.2). A negative-curvature direction is followed to the region's boundary
    /// rather than damped by a global shift, and most iterations cost a few sparse
    /// products and triangular solves instead of a factorisation.
    /// [`NewtonSettings::projection`] and [`NewtonSettings::reuse_factorization`] are
    /// not used (the factor is kept by its own rule).
    TrustRegion,
}

/// Residual contraction of a fresh Newton step above which its factor is kept
/// (see [`NewtonSettings::reuse_factorization`]).
pub const REUSE_AFTER_FRESH: f64 = 10.0;
/// Residual contraction of a step with a reused factor above which it is kept again.
pub const REUSE_AFTER_REUSED: f64 = 4.0;

/// Attempts of the diagonal-shift search: from 1e-8 of the mean diagonal, doubling, 60
/// attempts reach 1e10 of it.
const SHIFT_ATTEMPTS: usize = 60;

/// How Newton makes its matrix positive definite.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HessianProjection {
    /// Always project every element block (robust, linear convergence near folds).
    Always,
    /// Use the exact Hessian; project only when it fails to factorise (quadratic
    /// convergence whenever the exact Hessian is positive definite).
    WhenIndefinite,
    /// Never project: a non-PD matrix gets the smallest diagonal shift (within 2×) that
    /// factorises. Leaves saddles fast (the step follows negative curvature); best for
    /// mass-spring cloth, whose compressed springs make the exact Hessian indefinite.
    Never,
}

impl Default for NewtonSettings {
    fn default() -> Self {
        Self {
            tolerance: 1e-6,
            max_iterations: 100,
            armijo: 1e-4,
            max_line_search: 40,
            projection: HessianProjection::WhenIndefinite,
            reuse_factorization: false,
            globalization: Globalization::LineSearch,
            retry_other_strategy: true,
            exact_hessian_after_rises: None,
            iteration_budget: None,
            factorization_budget: None,
        }
    }
}

/// A factorised Newton matrix ([`NewtonSolver::factorize_at`]) and what it cost.
#[derive(Debug)]
pub struct Factorized {
    pub factor: weft_linalg::CholeskyFactor,
    /// Diagonally shifted attempts it needed (0: the matrix factorised as assembled).
    pub shifts: usize,
    /// The shift `τ` of the matrix factorised (0 when `shifts` is 0).
    pub shift: f64,
    /// Numeric factorisations attempted, failed ones included.
    pub numeric: usize,
    /// Whether the factorised matrix is the per-element PSD projection of the Hessian
    /// (else the true Hessian, shifted if `shifts > 0`).
    pub projected: bool,
}

/// What one minimisation did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct NewtonReport {
    pub iterations: usize,
    /// Final max-norm residual force on free DOFs (N).
    pub residual: f64,
    pub initial_residual: f64,
    /// Final total energy (J).
    pub energy: f64,
    /// Total step halvings over all iterations.
    pub line_search_halvings: usize,
    /// Times a diagonal shift was needed to make the Newton matrix positive definite.
    pub regularizations: usize,
    /// Numeric Cholesky factorisations attempted, failed ones included: for each matrix
    /// factorised, the unprojected attempt, the projected second attempt of
    /// [`HessianProjection::WhenIndefinite`] and every diagonally shifted attempt. One per
    /// iteration where the matrix is positive definite at the first attempt, unless
    /// [`NewtonSettings::reuse_factorization`] keeps a factor.
    pub factorizations: usize,
    #[serde(with = "duration_seconds")]
    pub time: Duration,
    /// Residual after each iteration (N), for convergence studies.
    #[serde(skip)]
    pub residual_history: Vec<f64>,
    /// The diagonal shift `τ` of the matrix each line-search iteration stepped with (N/m;
    /// 0 where the matrix factorised as assembled or was projected), beside
    /// [`NewtonReport::residual_history`]: where a global shift holds Newton back.
    #[serde(skip)]
    pub shift_history: Vec<f64>,
    /// The round-off floor of the residual force at the last factorisation (N); the
    /// tolerance applied is the larger of this and the requested one.
    pub residual_floor: f64,
    /// Conjugate-gradient iterations (trust region only; each one a sparse product and a
    /// preconditioner solve).
    pub cg_iterations: usize,
    /// Trust-region steps rejected because the energy did not follow the model (each is
    /// counted in `iterations` too).
    pub rejected_steps: usize,
    /// The projection of the retry when the configured strategy did not converge and the
    /// retry did ([`NewtonSettings::retry_other_strategy`]); the report's counts are the
    /// retry's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fallback: Option<HessianProjection>,
    /// The first iteration that stepped with the shifted exact Hessian after the switch of
    /// [`NewtonSettings::exact_hessian_after_rises`] (1-based), if it switched.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exact_from_iteration: Option<usize>,
    /// The minimisation ended at [`NewtonSettings::iteration_budget`] above the
    /// tolerance, and its last iterate was accepted.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub stopped_at_budget: bool,
}

impl NewtonReport {
    /// The report of a minimisation that has not iterated yet.
    fn starting(energy: f64, residual: f64) -> Self {
        Self {
            iterations: 0,
            residual,
            initial_residual: residual,
            energy,
            line_search_halvings: 0,
            regularizations: 0,
            factorizations: 0,
            time: Duration::ZERO,
            residual_history: Vec::new(),
            shift_history: Vec::new(),
            residual_floor: 0.0,
            cg_iterations: 0,
            rejected_steps: 0,
            fallback: None,
            exact_from_iteration: None,
            stopped_at_budget: false,
        }
    }
}

/// Factorises `matrix + τI` with the smallest `τ` (within 2×) that works, starting at a
/// quarter of `last_shift`, from 1e-8 of the mean diagonal and doubling: `(factor,
/// attempts, τ)`.
fn shifted_factor(
    cholesky: &CholeskySolver,
    matrix: &SymmetricMatrix,
    last_shift: f64,
) -> Result<(weft_linalg::CholeskyFactor, usize, f64)> {
    let n = matrix.dim();
    let mean_diag = matrix.diagonal().map(f64::abs).sum::<f64>() / n as f64;
    let floor = 1e-8 * mean_diag.max(1e-12);
    let mut shift = floor.max(0.25 * last_shift);
    let mut shifted = matrix.clone();
    for attempt in 1..=SHIFT_ATTEMPTS {
        if attempt > 1 {
            shifted.copy_values_from(matrix);
        }
        shifted.add_diagonal(shift);
        if let Ok(f) = cholesky.factorize(&shifted) {
            return Ok((f, attempt, shift));
        }
        shift *= 2.0;
    }
    Err(weft_linalg::Error::NotPositiveDefinite.into())
}

mod duration_seconds {
    pub fn serialize<S: serde::Serializer>(d: &std::time::Duration, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_f64(d.as_secs_f64())
    }
}

/// Minimises a sum of [`Energy`] terms over free DOFs, holding fixed DOFs where they are.
///
/// The sparsity pattern and its symbolic Cholesky factorisation are computed once in
/// [`NewtonSolver::new`]; every iteration only assembles values and refactorises
/// numerically.
#[derive(Debug)]
pub struct NewtonSolver {
    fixed: Vec<bool>,
    hessian: SymmetricMatrix,
    cholesky: CholeskySolver,
    grad: Vec<f64>,
    dir: Vec<f64>,
    trial: Vec<f64>,
    last_shift: f64,
    /// The trust region's preconditioner: the projected Hessian, its factor while it
    /// serves, and the radius the last call ended with.
    preconditioner: trust_region::Preconditioner,
    /// The last matrix the line-search Newton of the last minimisation factorised afresh
    /// ([`NewtonSolver::take_last_factor`]).
    last_factor: Option<Factorized>,
}

impl NewtonSolver {
    /// Prepares a solver for `terms` over `num_dofs` DOFs; `fixed[i]` holds DOF `i`.
    pub fn new(num_dofs: usize, terms: &[&dyn Energy], fixed: Vec<bool>) -> Result<Self> {
        if fixed.len() != num_dofs {
            return Err(Error::LengthMismatch {
                what: "fixed-DOF mask",
                expected: num_dofs,
                got: fixed.len(),
            });
        }
        if !num_dofs.is_multiple_of(3) {
            return Err(Error::LengthMismatch {
                what: "DOFs (3 per vertex)",
                expected: num_dofs / 3 * 3,
                got: num_dofs,
            });
        }
        let pairs = crate::energy::checked_pairs(num_dofs, terms)?;
        let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(num_dofs / 3, pairs));
        let cholesky = CholeskySolver::new(pattern.clone())?;
        Ok(Self {
            fixed,
            hessian: SymmetricMatrix::zeros(pattern.clone()),
            cholesky,
            grad: vec![0.0; num_dofs],
            dir: vec![0.0; num_dofs],
            trial: vec![0.0; num_dofs],
            last_shift: 0.0,
            preconditioner: trust_region::Preconditioner::new(pattern),
            last_factor: None,
        })
    }

    /// The last factorisation the previous [`minimize`](Self::minimize) made afresh
    /// (line search only; `None` if it factorised nothing, e.g. a start already
    /// converged), handed over rather than dropped. Its matrix is the Newton matrix at an
    /// iterate one or more steps before the minimiser: close to the Hessian there, so a
    /// preconditioner with which CG solves an adjoint system at the minimiser in a few
    /// iterations instead of a new factorisation.
    pub fn take_last_factor(&mut self) -> Option<Factorized> {
        self.last_factor.take()
    }

    pub fn fixed(&self) -> &[bool] {
        &self.fixed
    }

    /// Replaces the fixed-DOF mask (the pattern does not depend on it).
    pub fn set_fixed(&mut self, fixed: Vec<bool>) -> Result<()> {
        if fixed.len() != self.fixed.len() {
            return Err(Error::LengthMismatch {
                what: "fixed-DOF mask",
                expected: self.fixed.len(),
                got: fixed.len(),
            });
        }
        // A kept preconditioner eliminated the old fixed DOFs.
        self.preconditioner.invalidate();
        self.fixed = fixed;
        Ok(())
    }

    /// The round-off floor of the residual force at `x`: `64 ε · max_i H_ii · max_j |x_j|`
    /// over free DOFs, with `H` the Newton matrix last assembled. Internal forces are sums
    /// of terms like `k (x_a − x_b)` whose rounding error is about `ε k |x|`, and `H_ii`
    /// bounds the stiffness `Σ k` meeting at a DOF; below this floor the residual carries
    /// no information, whatever the requested tolerance. Stiff materials, tiny time steps
    /// (inertia `m/Δt²`) and coordinates far from the origin all raise it.
    fn residual_floor(&self, x: &[f64]) -> f64 {
        let free = || (0..x.len()).filter(|&i| !self.fixed[i]);
        let h_max = weft_linalg::max_abs(
            self.hessian
                .diagonal()
                .zip(&self.fixed)
                .filter(|(_, f)| !**f)
                .map(|(h, _)| h),
        );
        let x_max = weft_linalg::max_abs(free().map(|i| x[i]));
        ROUNDOFF_FLOOR_FACTOR * f64::EPSILON * h_max * x_max
    }

    /// Max-norm of the free-DOF entries of `grad`; `+∞` if any of them is not finite.
    pub fn free_residual(&self, grad: &[f64]) -> f64 {
        weft_linalg::max_abs(grad.iter().zip(&self.fixed).filter(|(_, f)| !**f).map(|(g, _)| *g))
    }

    /// The assembled (unconstrained) Hessian at the last evaluated point, for adjoint solves.
    pub fn hessian(&self) -> &SymmetricMatrix {
        &self.hessian
    }

    /// Assembles the Hessian of `terms` at `x` (projected per `projection`) with fixed
    /// DOFs eliminated and factorises it, shifting the diagonal if needed.
    pub fn factorize_at(
        &mut self,
        terms: &[&dyn Energy],
        x: &[f64],
        projection: HessianProjection,
    ) -> Result<Factorized> {
        let attempts: &[bool] = match projection {
            HessianProjection::Always => &[true],
            HessianProjection::WhenIndefinite => &[false, true],
            HessianProjection::Never => &[false],
        };
        for (k, &project) in attempts.iter().enumerate() {
            self.hessian.set_zero();
            for t in terms {
                t.add_hessian(x, project, &mut self.hessian);
            }
            self.hessian.constrain_dofs(&self.fixed);
            match self.cholesky.factorize(&self.hessian) {
                Ok(factor) => {
                    return Ok(Factorized {
                        factor,
                        shifts: 0,
                        shift: 0.0,
                        numeric: k + 1,
                        projected: project,
                    });
                }
                Err(weft_linalg::Error::NotPositiveDefinite) if k + 1 < attempts.len() => continue,
                Err(weft_linalg::Error::NotPositiveDefinite) => break,
                Err(e) => return Err(e.into()),
            }
        }
        // Singular or indefinite (free rigid modes, an unprojected saddle): add τI with τ
        // grown twofold until the matrix factorises, starting at a quarter of the last τ
        // that worked (Nocedal & Wright, *Numerical Optimization*, Alg. 3.3, with the
        // previous iteration's shift remembered). Consecutive Hessians need similar
        // shifts, so this costs two or three factorisations, and τ ends within 2× of the
        // smallest that works: the step then follows the negative-curvature directions
        // instead of damping them, which is what lets Newton leave a saddle (a flat sheet
        // that must wrinkle: 180 iterations on the 65 × 65 mass-spring sheet's first frame
        // against 1191 with projected Hessians, docs/CLOTH.md).
        // The shift changes only the step, never the minimiser.
        let (factor, shifts, shift) = shifted_factor(&self.cholesky, &self.hessian, self.last_shift)?;
        self.last_shift = shift;
        Ok(Factorized {
            factor,
            shifts,
            shift,
            numeric: attempts.len() + shifts,
            projected: *attempts.last().unwrap_or(&false),
        })
    }

    /// The Newton direction `d = −H⁻¹ g` on free DOFs into `self.dir`, or steepest descent
    /// if round-off makes `d` ascend (impossible for a PD matrix otherwise); returns the
    /// slope `dᵀg`.
    fn direction(&mut self, factor: &weft_linalg::CholeskyFactor, grad: &[f64]) -> f64 {
        for (i, d) in self.dir.iter_mut().enumerate() {
            *d = if self.fixed[i] { 0.0 } else { -grad[i] };
        }
        factor.solve_in_place(&mut self.dir);
        let slope: f64 = self.dir.iter().zip(grad).map(|(d, g)| d * g).sum();
        if slope < 0.0 {
            return slope;
        }
        for (i, d) in self.dir.iter_mut().enumerate() {
            *d = if self.fixed[i] { 0.0 } else { -grad[i] };
        }
        self.dir.iter().zip(grad).map(|(d, g)| d * g).sum()
    }

    /// Chooses the step along `self.dir` and leaves the new point in `self.trial`;
    /// returns its energy and whether it is the full Newton step, or `None` if no
    /// decrease is possible. `grad` is scratch (it holds the gradient at `x` again when
    /// `None` is returned).
    ///
    /// First, backtracking Armijo on the energy, whose changes are summed term by term
    /// (affine terms exactly) so that a body far from the origin does not drown them in
    /// the round-off of `−f·x`. An Armijo step that is vanishingly short, or whose
    /// decrease is below the energy's round-off, "passes" by noise and Newton stalls: near
    /// the minimiser of a stiff problem energy comparisons carry no information. Then the
    /// step is judged by the residual force instead (backtracking from the full step),
    /// keeping the tiny Armijo step only if that fails too.
    fn line_search(
        &mut self,
        terms: &[&dyn Energy],
        x: &[f64],
        grad: &mut [f64],
        energy: f64,
        residual: f64,
        slope: f64,
        settings: &NewtonSettings,
        report: &mut NewtonReport,
    ) -> Option<(f64, bool)> {
        let n = x.len();
        // Each non-affine term's value at `x`, once: trial changes are then one evaluation
        // per term, and their sum of magnitudes is the energy's round-off scale.
        let at_x: Vec<Option<f64>> = terms.iter().map(|t| (!t.is_affine()).then(|| t.value(x))).collect();
        let roundoff_scale: f64 = at_x.iter().flatten().map(|v| v.abs()).sum();
        let change = |trial: &[f64]| -> f64 {
            terms
                .iter()
                .zip(&at_x)
                .map(|(t, v)| match v {
                    Some(v) => t.value(trial) - v,
                    None => t.value_change(x, trial),
                })
                .sum()
        };
        let mut alpha = 1.0;
        let mut armijo = None;
        for _ in 0..=settings.max_line_search {
            for i in 0..n {
                self.trial[i] = x[i] + alpha * self.dir[i];
            }
            let de = change(&self.trial);
            if de.is_finite() && de <= settings.armijo * alpha * slope {
                armijo = Some(energy + de);
                break;
            }
            alpha *= 0.5;
            report.line_search_halvings += 1;
        }
        let measurable = -alpha * slope > 64.0 * f64::EPSILON * roundoff_scale;
        if let Some(e) = armijo {
            if alpha >= MIN_TRUSTED_STEP && measurable {
                return Some((e, alpha == 1.0));
            }
        }
        let tiny = armijo.map(|e| (self.trial.clone(), e));
        let mut beta = 1.0;
        for _ in 0..12 {
            for i in 0..n {
                self.trial[i] = x[i] + beta * self.dir[i];
            }
            total_gradient(terms, &self.trial, grad);
            let e = energy + change(&self.trial);
            let r = self.free_residual(grad);
            if e.is_finite() && r.is_finite() && r < residual {
                return Some((e, beta == 1.0));
            }
            beta *= 0.5;
        }
        match tiny {
            Some((t, e)) => {
                self.trial.copy_from_slice(&t);
                Some((e, false))
            }
            None => {
                total_gradient(terms, x, grad);
                None
            }
        }
    }

    /// Minimises `Σ terms` from `x` (updated in place). Fixed DOFs keep their values.
    /// A minimisation that does not converge is retried once with the other strategy
    /// ([`NewtonSettings::retry_other_strategy`]); if that fails too, the first error is
    /// returned.
    pub fn minimize(
        &mut self,
        terms: &[&dyn Energy],
        x: &mut [f64],
        settings: &NewtonSettings,
    ) -> Result<NewtonReport> {
        let start = settings.retry_other_strategy.then(|| x.to_vec());
        let first = match self.minimize_once(terms, x, settings) {
            Err(e @ Error::NotConverged { .. }) => e,
            other => return other,
        };
        let other = match (settings.globalization, settings.projection) {
            (Globalization::TrustRegion, p) => p,
            (_, HessianProjection::Never) => HessianProjection::WhenIndefinite,
            (_, HessianProjection::WhenIndefinite) => HessianProjection::Never,
            (_, HessianProjection::Always) => return Err(first),
        };
        let Some(start) = start else {
            return Err(first);
        };
        x.copy_from_slice(&start);
        let retry = NewtonSettings {
            projection: other,
            globalization: Globalization::LineSearch,
            ..*settings
        };
        let mut report = self.minimize_once(terms, x, &retry).map_err(|_| first)?;
        report.fallback = Some(other);
        Ok(report)
    }

    /// One minimisation with `settings`' strategy, no retry.
    fn minimize_once(
        &mut self,
        terms: &[&dyn Energy],
        x: &mut [f64],
        settings: &NewtonSettings,
    ) -> Result<NewtonReport> {
        let start = Instant::now();
        self.last_factor = None;
        let (energy, residual) = self.start(terms, x)?;
        let mut progress = Progress {
            energy,
            residual,
            floor: 0.0,
            grad: std::mem::take(&mut self.grad),
            report: NewtonReport::starting(energy, residual),
        };
        let result = match settings.globalization {
            Globalization::LineSearch => self.line_search_steps(terms, x, settings, &mut progress),
            Globalization::TrustRegion => self.trust_region_steps(terms, x, settings, &mut progress),
        };
        self.grad = std::mem::take(&mut progress.grad);
        let mut report = progress.report;
        report.residual = progress.residual;
        report.energy = progress.energy;
        report.time = start.elapsed();
        result.map(|_| report)
    }

    /// Checks `x` against the solver and evaluates the energy and gradient there (into
    /// `self.grad`): `(energy, free residual)`.
    fn start(&mut self, terms: &[&dyn Energy], x: &[f64]) -> Result<(f64, f64)> {
        if x.len() != self.fixed.len() {
            return Err(Error::LengthMismatch {
                what: "positions",
                expected: self.fixed.len(),
                got: x.len(),
            });
        }
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "initial position",
                dof: i,
            });
        }
        let energy = total_value(terms, x);
        total_gradient(terms, x, &mut self.grad);
        if let Some(i) = self.grad.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "initial gradient",
                dof: i,
            });
        }
        Ok((energy, self.free_residual(&self.grad)))
    }

    /// Moves `x` to `self.trial` (an accepted step), evaluates the gradient there and
    /// records the residual. Returns whether the step could not change any coordinate by
    /// more than its rounding, so Newton can make no further progress — the solve then
    /// ends converged if the residual is within 16× the tolerance applied, with
    /// [`Error::NotConverged`] otherwise.
    fn take_step(
        &mut self,
        terms: &[&dyn Energy],
        x: &mut [f64],
        settings: &NewtonSettings,
        progress: &mut Progress,
    ) -> Result<bool> {
        let xmax = weft_linalg::max_abs(x.iter().copied());
        let moved = weft_linalg::max_abs(x.iter().zip(&self.trial).map(|(a, b)| b - a));
        x.copy_from_slice(&self.trial);
        total_gradient(terms, x, &mut progress.grad);
        if let Some(i) = progress.grad.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "gradient",
                dof: i,
            });
        }
        progress.residual = self.free_residual(&progress.grad);
        progress.report.residual_history.push(progress.residual);
        let stalled = moved <= 4.0 * f64::EPSILON * xmax;
        if stalled && progress.residual > 16.0 * progress.tolerance(settings) {
            return Err(progress.not_converged(progress.tolerance(settings)));
        }
        Ok(stalled)
    }

    /// Newton iterations with the line search (see [`Globalization::LineSearch`]).
    fn line_search_steps(
        &mut self,
        terms: &[&dyn Energy],
        x: &mut [f64],
        settings: &NewtonSettings,
        progress: &mut Progress,
    ) -> Result<()> {
        // The factor in use (the last fresh one), and whether the next step reuses it.
        let mut current: Option<Factorized> = None;
        let mut hold = false;
        // The projection in use, and the run of projected iterations whose residual rose
        // (`NewtonSettings::exact_hessian_after_rises`).
        let mut projection = settings.projection;
        let mut rises = 0;
        // Fresh factorisations made so far (`NewtonSettings::factorization_budget`).
        let mut fresh_factors = 0;
        while progress.iterate(settings)? {
            let budget_spent = settings.factorization_budget.is_some_and(|b| fresh_factors >= b);
            let fresh = current.is_none() || !(hold || budget_spent);
            if fresh {
                fresh_factors += 1;
                let f = self.factorize_at(terms, x, projection)?;
                progress.report.regularizations += f.shifts;
                progress.report.factorizations += f.numeric;
                progress.floor = self.residual_floor(x);
                progress.report.residual_floor = progress.floor;
                current = Some(f);
            }
            hold = false;
            let Some(factorized) = current.as_ref() else {
                unreachable!("a factor was just made")
            };
            progress
                .report
                .shift_history
                .push(if factorized.shifts > 0 { factorized.shift } else { 0.0 });
            let slope = self.direction(&factorized.factor, &progress.grad);
            let choice = self.line_search(
                terms,
                x,
                &mut progress.grad,
                progress.energy,
                progress.residual,
                slope,
                settings,
                &mut progress.report,
            );
            let Some((trial_energy, full_step)) = choice else {
                // No decrease is possible along a descent direction: the problem is
                // broken or badly scaled. Stop with a clear error rather than loop.
                return Err(progress.not_converged(settings.tolerance));
            };
            progress.energy = trial_energy;
            let previous = progress.residual;
            let projected = factorized.projected;
            if self.take_step(terms, x, settings, progress)? {
                break;
            }
            if let Some(limit) = settings.exact_hessian_after_rises {
                if projection == HessianProjection::WhenIndefinite && projected {
                    rises = if progress.residual > previous { rises + 1 } else { 0 };
                    if rises >= limit {
                        projection = HessianProjection::Never;
                        progress.report.exact_from_iteration = Some(progress.report.iterations + 1);
                        // The held factor is the projected one: the next step factorises.
                        hold = false;
                        continue;
                    }
                }
            }
            if settings.reuse_factorization && full_step {
                let needed = if fresh { REUSE_AFTER_FRESH } else { REUSE_AFTER_REUSED };
                hold = progress.residual * needed <= previous;
            }
        }
        self.last_factor = current;
        Ok(())
    }
}

/// One minimisation's running state, shared by both globalisations.
struct Progress {
    /// Total energy at the current point (J).
    energy: f64,
    /// Max-norm residual force on free DOFs at the current point (N).
    residual: f64,
    /// The residual's round-off floor at the last assembly (see `residual_floor`).
    floor: f64,
    /// The gradient at the current point.
    grad: Vec<f64>,
    report: NewtonReport,
}

impl Progress {
    /// The tolerance applied: the requested one or the round-off floor, the larger.
    fn tolerance(&self, settings: &NewtonSettings) -> f64 {
        settings.tolerance.max(self.floor)
    }

    /// Starts the next iteration: `false` once converged, an error at the iteration cap.
    fn iterate(&mut self, settings: &NewtonSettings) -> Result<bool> {
        if self.residual <= self.tolerance(settings) {
            return Ok(false);
        }
        if settings.iteration_budget.is_some_and(|b| self.report.iterations >= b) {
            self.report.stopped_at_budget = true;
            return Ok(false);
        }
        if self.report.iterations >= settings.max_iterations {
            return Err(self.not_converged(self.tolerance(settings)));
        }
        self.report.iterations += 1;
        Ok(true)
    }

    fn not_converged(&self, tolerance: f64) -> Error {
        Error::NotConverged {
            iterations: self.report.iterations,
            residual: self.residual,
            tolerance,
        }
    }
}
