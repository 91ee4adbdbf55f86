//! The guard's error estimate: how far a frame can be from the step's minimiser, from the
//! step's residual force and a certified lower bound on the step's curvature
//! (docs/GUARD.md, "The estimate").

use std::sync::Arc;

use weft_linalg::{CholeskyFactor, CholeskySolver, SymmetricMatrix, SymmetricPattern};

use crate::energy::{Energy, checked_pairs};
use crate::error::Result;
use crate::integrators::ImplicitEuler;

/// Power iterations behind the Collatz–Wielandt bound on the negative curvature
/// (docs/GUARD.md): every iterate gives a valid bound, more only tighten it.
pub const CERTIFICATE_ITERATIONS: usize = 8;

/// Conjugate-gradient iterations at most for the Newton-step estimate (docs/GUARD.md,
/// Eq. G6); a proposal close to the minimiser needs far fewer.
pub const NEWTON_ESTIMATE_ITERATIONS: usize = 60;

/// Relative residual the Newton-step estimate's CG solve stops at, with the Jacobi
/// preconditioner (whose iterations are capped) and with a Cholesky factor (whose
/// iterations are a few triangular solves each). A residual of 1 % can still leave the
/// step's length several per cent off where the residual lies along the soft modes the
/// factor captures; a tenth of that costs the lagged factor one or two iterations.
const NEWTON_ESTIMATE_TOLERANCE: f64 = 1e-2;
const NEWTON_ESTIMATE_TOLERANCE_FACTORED: f64 = 1e-3;

/// CG iterations a lagged factor is given before the estimate factorises afresh; more than
/// half of them also refreshes the factor for the next estimate, and a failure makes the
/// following estimates factorise at once, for 1, 2, 4, … frames (docs/GUARD.md, "The
/// preconditioner").
pub const LAGGED_FACTOR_ITERATIONS: usize = 16;

/// The most estimates in a row that factorise afresh, after lagged factors failed,
/// before one is tried again.
const MAX_LAGGED_BACKOFF: usize = 16;

/// How the Newton-step estimate's CG solve (Eq. G6) is preconditioned.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EstimatePreconditioner {
    /// The diagonal of the step's matrix: no factorisation, but on a large wrinkling
    /// sheet [`NEWTON_ESTIMATE_ITERATIONS`] of CG stop far short of the Newton step, and
    /// the estimate reads low (CG's iterates grow monotonically in length from zero).
    Jacobi,
    /// A Cholesky factor of the projected step matrix `M/Δt² + H⁺` from an earlier frame,
    /// preconditioning CG on that matrix (the estimate is then the projected Newton
    /// step's length), refreshed when CG does not converge within
    /// [`LAGGED_FACTOR_ITERATIONS`] with it. Where the step matrix changes little from frame to
    /// frame one factorisation serves many estimates, each a few triangular solves; on a
    /// wrinkling sheet most frames need their own.
    #[default]
    LaggedCholesky,
}

/// What the residual at a frame says about its distance from the step's minimiser `x*`.
///
/// Two figures (docs/GUARD.md, "The estimate"):
/// - the **estimate** ([`ErrorEstimate::mm`]): the length of the Newton step from the
///   frame, `‖A⁻¹ ∇E(x)‖_M` with `A` the step's Hessian there (Eq. G6) — exact to first
///   order in the distance, which is what the guard's tolerance judges by default;
/// - the **bound** ([`ErrorEstimate::bound_mm`]): `‖∇E(x)‖_{M⁻¹} / μ` (Eq. G3), a rigorous
///   upper bound where the step's modulus `μ` is certified positive, `None` elsewhere.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ErrorEstimate {
    /// `‖∇E(x)‖_{M⁻¹}` over the free DOFs (N/√kg).
    pub residual_m_inv: f64,
    /// The largest free-DOF residual force `|∂E/∂x_i|` (N): what Newton's tolerance bounds.
    pub residual_max: f64,
    /// The certified lower bound on the modulus, `1/Δt² − ρ` (1/s²); not positive where
    /// the negative curvature `ρ` may cancel the mass term.
    pub modulus: f64,
    /// Whether the strong-convexity condition was certified at the frame (`modulus > 0`),
    /// so that [`ErrorEstimate::bound_mm`] is a bound.
    pub certified: bool,
    /// The bound of Eq. G3 as a mass-weighted RMS per coordinate (mm), where certified.
    pub bound_mm: Option<f64>,
    /// The Newton-step estimate of `‖x − x*‖_M` (m·√kg).
    pub distance: f64,
    /// The same as a mass-weighted RMS per coordinate (mm):
    /// `1000 · distance / √(3 Σ_v m_v)`, which equals M_rms for uniform masses.
    pub mm: f64,
    /// The estimate is the length of the Newton step with the positive semi-definite
    /// projection `H⁺` of the Hessian, not the exact `H` (Eq. G6): always with the
    /// lagged Cholesky preconditioner; with Jacobi where CG found the exact step matrix
    /// indefinite.
    pub projected: bool,
    /// CG iterations of the estimate's Newton-step solve.
    pub cg_iterations: usize,
    /// Numeric factorisations the estimate made for its preconditioner (0 when the
    /// lagged factor served, or with [`EstimatePreconditioner::Jacobi`]).
    pub factorizations: usize,
}

/// The per-mesh data and scratch of [`ErrorEstimate`]s for one integrator.
#[derive(Debug)]
pub(crate) struct Estimator {
    /// Mass of each DOF's vertex (kg).
    dof_mass: Vec<f64>,
    free: Vec<bool>,
    /// `√(3 Σ_v m_v)` (√kg): the mass-weighted RMS's denominator.
    rms_scale: f64,
    /// `√(Σ_free 1/m_i)` (1/√kg): `‖g‖_{M⁻¹} ≤ ‖g‖_∞ · this`.
    max_to_m_inv: f64,
    exact: SymmetricMatrix,
    projected: SymmetricMatrix,
    grad: Vec<f64>,
    /// The Newton-step estimate's solution.
    step: Vec<f64>,
    preconditioner: EstimatePreconditioner,
    /// The symbolic analysis of the step matrix's pattern, made at the first
    /// factorisation.
    cholesky: Option<CholeskySolver>,
    /// The last factor of the projected step matrix; how many more estimates factorise
    /// afresh without trying it, and the current run of frames skipped after a failure.
    lagged: Option<CholeskyFactor>,
    skip_lagged: usize,
    backoff: usize,
}

impl Estimator {
    pub(crate) fn new(integrator: &ImplicitEuler, preconditioner: EstimatePreconditioner) -> Result<Self> {
        let n = integrator.positions().len();
        let terms: Vec<&dyn Energy> = integrator.terms().iter().map(|t| t.as_ref()).collect();
        let pairs = checked_pairs(n, &terms)?;
        let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(n / 3, pairs));
        let dof_mass: Vec<f64> = (0..n).map(|i| integrator.masses()[i / 3]).collect();
        let free: Vec<bool> = integrator.fixed().iter().map(|f| !f).collect();
        let total: f64 = integrator.masses().iter().sum();
        let inv: f64 = (0..n).filter(|&i| free[i]).map(|i| 1.0 / dof_mass[i]).sum();
        Ok(Self {
            dof_mass,
            free,
            rms_scale: (3.0 * total).sqrt(),
            max_to_m_inv: inv.sqrt(),
            exact: SymmetricMatrix::zeros(pattern.clone()),
            projected: SymmetricMatrix::zeros(pattern),
            grad: vec![0.0; n],
            step: vec![0.0; n],
            preconditioner,
            cholesky: None,
            lagged: None,
            skip_lagged: 0,
            backoff: 0,
        })
    }

    /// A mass-weighted distance (m·√kg) as a mass-weighted RMS per coordinate (mm).
    pub(crate) fn to_mm(&self, distance: f64) -> f64 {
        1e3 * distance / self.rms_scale
    }

    /// The mass-weighted distance (m·√kg) of `mm`.
    pub(crate) fn distance_of_mm(&self, mm: f64) -> f64 {
        1e-3 * mm * self.rms_scale
    }

    /// The largest free-DOF residual force (N) that guarantees `‖g‖_{M⁻¹} ≤ bound`.
    pub(crate) fn max_residual_for(&self, bound: f64) -> f64 {
        bound / self.max_to_m_inv.max(f64::MIN_POSITIVE)
    }

    /// `‖a − b‖_M` over all DOFs (m·√kg).
    pub(crate) fn m_norm(&self, a: &[f64], b: &[f64]) -> f64 {
        a.iter()
            .zip(b)
            .zip(&self.dof_mass)
            .map(|((a, b), m)| m * (a - b).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// The estimate at frame `x` of the integrator's next step (its history is the
    /// integrator's current state). The residual is the integrator's own gradient of
    /// Tan et al. Eq. 4 ([`ImplicitEuler::l_phys_gradient`]).
    pub(crate) fn estimate(&mut self, integrator: &ImplicitEuler, x: &[f64]) -> Result<ErrorEstimate> {
        integrator.l_phys_gradient(
            integrator.previous_positions(),
            integrator.positions(),
            x,
            &mut self.grad,
        )?;
        let (mut sq, mut max) = (0.0f64, 0.0f64);
        for i in 0..x.len() {
            if self.free[i] {
                sq += self.grad[i] * self.grad[i] / self.dof_mass[i];
                max = max.max(self.grad[i].abs());
            } else {
                self.grad[i] = 0.0;
            }
        }
        // NaN compares false: a non-finite gradient must not read as a zero residual.
        if !sq.is_finite() || self.grad.iter().any(|g| !g.is_finite()) {
            return Ok(Self::non_finite());
        }
        let inv_dt2 = 1.0 / integrator.dt().powi(2);
        self.assemble(integrator, x);
        let modulus = inv_dt2 - self.negative_curvature();
        let certified = modulus > 0.0;
        let residual_m_inv = sq.sqrt();
        let (distance, projected, cg_iterations, factorizations) = self.newton_step_length(inv_dt2)?;
        Ok(ErrorEstimate {
            residual_m_inv,
            residual_max: max,
            modulus,
            certified,
            bound_mm: certified.then(|| self.to_mm(residual_m_inv / modulus)),
            distance,
            mm: self.to_mm(distance),
            projected,
            cg_iterations,
            factorizations,
        })
    }

    /// The estimate of a frame whose residual is not finite.
    pub(crate) fn non_finite() -> ErrorEstimate {
        ErrorEstimate {
            residual_m_inv: f64::INFINITY,
            residual_max: f64::INFINITY,
            modulus: f64::NAN,
            certified: false,
            bound_mm: None,
            distance: f64::INFINITY,
            mm: f64::INFINITY,
            projected: false,
            cg_iterations: 0,
            factorizations: 0,
        }
    }

    /// The potential's exact and projected Hessians at `x`.
    fn assemble(&mut self, integrator: &ImplicitEuler, x: &[f64]) {
        self.exact.set_zero();
        self.projected.set_zero();
        for t in integrator.terms() {
            t.add_hessian(x, false, &mut self.exact);
            t.add_hessian(x, true, &mut self.projected);
        }
    }

    /// `‖δ‖_M` for the Newton step `A δ = ∇E(x)`, `A = M/Δt² + H` on the free DOFs
    /// (Eq. G6), by preconditioned CG from the assembled Hessians. With Jacobi, on the
    /// exact `H` where CG finds `A` positive along every direction it explores, else on
    /// the projected `H⁺` (positive definite with the mass term). With the lagged factor,
    /// on the projected `A`, the matrix it is a factor of: CG on the exact `A` with it
    /// spends tens of iterations before it meets the negative curvature of a wrinkling
    /// sheet. Returns the length, whether it is the projected step's, the CG iterations
    /// and the factorisations spent.
    fn newton_step_length(&mut self, inv_dt2: f64) -> Result<(f64, bool, usize, usize)> {
        let fixed: Vec<bool> = self.free.iter().map(|f| !f).collect();
        for matrix in [&mut self.exact, &mut self.projected] {
            for (i, m) in self.dof_mass.iter().enumerate() {
                matrix.add(i, i, m * inv_dt2);
            }
            matrix.constrain_dofs(&fixed);
        }
        if self.preconditioner == EstimatePreconditioner::Jacobi {
            let (length, projected, iterations, _) = self.solve_jacobi();
            return Ok((length, projected, iterations, 0));
        }
        let mut iterations = 0;
        match (&self.lagged, self.skip_lagged) {
            (Some(lagged), 0) => {
                let out = solve_projected(
                    &self.projected,
                    lagged,
                    &self.grad,
                    &mut self.step,
                    LAGGED_FACTOR_ITERATIONS,
                );
                if out.converged {
                    self.backoff = 0;
                    // A factor that needed most of its iterations is refreshed next time.
                    self.skip_lagged = usize::from(2 * out.iterations > LAGGED_FACTOR_ITERATIONS);
                    return Ok((self.m_length(), true, out.iterations, 0));
                }
                iterations += out.iterations;
                // Where frames keep outrunning their predecessor's factor (a wrinkling
                // sheet), try a lagged one ever more rarely: 1, 2, 4, … frames later.
                self.backoff = (2 * self.backoff).clamp(1, MAX_LAGGED_BACKOFF);
                self.skip_lagged = self.backoff;
            }
            (Some(_), _) => self.skip_lagged -= 1,
            (None, _) => {}
        }
        // No factor yet, or the last one is too far from this frame's matrix: a fresh
        // one solves the step in an iteration or two.
        self.refactorize()?;
        let factorizations = 1;
        let Some(fresh) = &self.lagged else {
            // The factorisation failed (a non-finite entry): Jacobi, as without one.
            let (length, projected, more, _) = self.solve_jacobi();
            return Ok((length, projected, iterations + more, factorizations));
        };
        let out = solve_projected(
            &self.projected,
            fresh,
            &self.grad,
            &mut self.step,
            NEWTON_ESTIMATE_ITERATIONS,
        );
        Ok((self.m_length(), true, iterations + out.iterations, factorizations))
    }

    /// `‖δ‖_M` of the last solve's step (m·√kg).
    fn m_length(&self) -> f64 {
        self.step
            .iter()
            .zip(&self.dof_mass)
            .map(|(d, m)| m * d * d)
            .sum::<f64>()
            .sqrt()
    }

    /// Factorises the projected step matrix as the preconditioner of later estimates.
    fn refactorize(&mut self) -> Result<()> {
        let solver = match self.cholesky.take() {
            Some(s) => s,
            None => CholeskySolver::new(self.projected.pattern().clone())?,
        };
        let factor = solver.factorize(&self.projected);
        self.cholesky = Some(solver);
        // A factor that fails (a non-finite entry) leaves the Jacobi fallback in place.
        self.lagged = factor.ok();
        Ok(())
    }

    /// Jacobi-preconditioned CG on the exact step matrix, then on the projected one if
    /// the exact one is indefinite: the step's length, whether it is the projected step's,
    /// the iterations, and whether the last solve converged.
    fn solve_jacobi(&mut self) -> (f64, bool, usize, bool) {
        let mut iterations = 0;
        for (matrix, projected) in [(&self.exact, false), (&self.projected, true)] {
            let diagonal: Vec<f64> = matrix.diagonal().collect();
            let jacobi = |r: &[f64], z: &mut [f64]| {
                for ((z, r), d) in z.iter_mut().zip(r).zip(&diagonal) {
                    // A non-positive diagonal (exact `H` only) falls back to the identity
                    // scale; the preconditioner must stay SPD.
                    *z = if *d > 0.0 { r / d } else { *r };
                }
            };
            let out = weft_linalg::pcg(
                matrix,
                jacobi,
                &self.grad,
                &mut self.step,
                NEWTON_ESTIMATE_TOLERANCE,
                NEWTON_ESTIMATE_ITERATIONS,
            );
            iterations += out.iterations;
            if !out.negative_curvature {
                return (self.m_length(), projected, iterations, out.converged);
            }
        }
        // The projected `A ⪰ M/Δt²` is positive definite: CG cannot find negative
        // curvature in it unless an entry is not finite.
        (f64::INFINITY, true, iterations, false)
    }

    /// A certified upper bound `ρ` (1/s²) on how far the assembled Hessian of the potential bends
    /// below zero in the mass metric: `H ⪰ −ρ M` on the free DOFs.
    ///
    /// The Hessian is the sum of element Hessians `H_e`; each term's projected assembly
    /// sums their positive semi-definite projections `H_e⁺`, so `H = H⁺ + N` with
    /// `H⁺ ⪰ 0` and `N = H − H⁺`. Then `H ⪰ N ⪰ −ρ(N) I`, and in the mass metric
    /// `ρ(M^{−½} N M^{−½}) ≤ ρ(|M^{−½} N M^{−½}|) ≤ max_i (|S| d)_i / d_i` for any positive
    /// `d` (Collatz–Wielandt). A few power iterations on `|S|` make `d` close to its Perron
    /// vector, which makes the bound tight; no factorisation is needed.
    fn negative_curvature(&self) -> f64 {
        let n = self.free.len();
        let pattern = self.exact.pattern().clone();
        // The off-projection part |S| as (row, col, value), free DOFs only.
        let mut entries = Vec::new();
        for (slot, r, c) in pattern.entries() {
            let v = self.exact.values()[slot] - self.projected.values()[slot];
            if v != 0.0 && self.free[r] && self.free[c] {
                entries.push((r, c, v.abs() / (self.dof_mass[r] * self.dof_mass[c]).sqrt()));
            }
        }
        if entries.is_empty() {
            return 0.0;
        }
        if entries.iter().any(|e| !e.2.is_finite()) {
            return f64::INFINITY;
        }
        let mut d: Vec<f64> = self.free.iter().map(|&f| if f { 1.0 } else { 0.0 }).collect();
        let mut y = vec![0.0; n];
        let mut best = f64::INFINITY;
        for _ in 0..CERTIFICATE_ITERATIONS {
            y.iter_mut().for_each(|v| *v = 0.0);
            for &(r, c, v) in &entries {
                y[r] += v * d[c];
                if r != c {
                    y[c] += v * d[r];
                }
            }
            let bound = (0..n)
                .filter(|&i| self.free[i])
                .map(|i| y[i] / d[i])
                .fold(0.0, f64::max);
            best = best.min(bound);
            // The next `d` must stay positive on every free DOF (rows of `|S|` may be zero).
            // Normalised to a largest entry of about 1, so repeated products cannot
            // overflow or underflow.
            let scale = weft_linalg::max_abs(y.iter().copied()).max(f64::MIN_POSITIVE);
            for i in (0..n).filter(|&i| self.free[i]) {
                d[i] = y[i] / scale + 1e-6;
            }
        }
        best
    }
}

/// CG on the projected step matrix `a`, preconditioned by a Cholesky `factor` of it or of
/// an earlier frame's, to [`NEWTON_ESTIMATE_TOLERANCE_FACTORED`] within `cap` iterations.
fn solve_projected(
    a: &SymmetricMatrix,
    factor: &CholeskyFactor,
    grad: &[f64],
    step: &mut [f64],
    cap: usize,
) -> weft_linalg::CgOutcome {
    let precondition = |r: &[f64], z: &mut [f64]| {
        z.copy_from_slice(r);
        factor.solve_in_place(z);
    };
    weft_linalg::pcg(a, precondition, grad, step, NEWTON_ESTIMATE_TOLERANCE_FACTORED, cap)
}
