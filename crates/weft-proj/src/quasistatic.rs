//! The quasistatic layer (Geng et al. §5–6): relax a predicted configuration `r̂` to the
//! equilibrium of a mass-spring cloth tied to `r̂` by zero-length springs, and
//! differentiate the equilibrium.
//!
//! # Forward (Geng et al. §5)
//!
//! `r* = argmin_r E_edge(r) + E_bending(r) + E_axial(r) + Σ_i ½ μ_i k_i ‖r_i − r̂_i‖²`
//!
//! - `E_edge = Σ ½ k_L (l_e − l̄_e)²` over mesh edges (weft-sim's `Springs`),
//! - `E_bending = Σ ½ k_B (l_e − l̄_e)²` over the fictitious edge across every hinge,
//! - `E_axial` the zero-length springs between each bending edge and its shared edge
//!   (Fig. 6, [`AxialSprings`]),
//! - zero-length springs to `r̂` with `k_i = k_Z m_i / m̄` (lumped rest masses over their
//!   mean) scaled by a global `μ` or per-vertex `μ_i` (weft-sim's `ZeroLengthSprings`).
//!
//! Minimised by weft-sim's Newton solver from `r̂` itself (which may be stretched or
//! inverted): per-spring PSD projection of the Hessian (the definiteness fix of Teran et
//! al. 2005) until near the equilibrium or until the projected steps stop lowering the
//! residual, then the true Hessian; an Armijo line search, sparse Cholesky with the
//! symbolic factor reused and each numeric factor kept for further steps while they
//! contract the residual force tenfold (Shamanskii's method;
//! `NewtonSettings::reuse_factorization`).
//!
//! # Backward (Geng et al. Eq. 12–16)
//!
//! At equilibrium `∇E_mat(r*) + W (r* − r̂) = 0` with `W = diag(μ_i k_i)`. Differentiating,
//! `H dr* = W dr̂ + k_i (r̂_i − r*_i) dμ_i` with `H` the *true* (unprojected) Hessian at
//! `r*`. One adjoint solve `H η = ∂E/∂r*` (Eq. 14) then gives
//! `∂E/∂r̂_i = μ_i k_i η_i` and `∂E/∂μ_i = k_i η_i · (r̂_i − r*_i)` (Eq. 16), whose sum over
//! vertices is `∂E/∂μ` for a global `μ`. The forward pass keeps Newton's last fresh
//! factor of the true Hessian — at an iterate a step or more before `r*`, where the
//! iterates converge quadratically, so it differs from `H(r*)` by `O(‖x − r*‖)` — and the
//! backward pass solves the adjoint system by conjugate gradients on `H(r*)`
//! preconditioned with it, to a relative residual of 1e-12 in a few iterations. That
//! replaces the factorisation at `r*` a forward pass used to make for the backward pass
//! (a third of a warm forward's cost). Where there is no such factor (a start that took
//! no true-Hessian step, a last factor that needed a diagonal shift) the forward pass
//! factorises `H(r*)` itself, and where CG does not converge the backward pass does.
//!
//! A saddle `r*` (an indefinite `H(r*)`, e.g. a squeezed sheet that has not buckled) is
//! refused with [`Error::NotAMinimum`]: by the forward pass when Newton's last factor
//! needed a shift, else by the backward pass when CG meets non-positive curvature and the
//! factorisation at `r*` needs a shift. A shifted matrix would give the gradient of
//! another problem.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use rayon::prelude::*;
use weft_linalg::{CholeskyFactor, SymmetricMatrix, SymmetricPattern};
use weft_mesh::TriMesh;
use weft_sim::energies::{Springs, ZeroLengthSprings};
use weft_sim::{Energy, HessianProjection, NewtonReport, NewtonSettings, NewtonSolver};

use crate::axial::{AxialSprings, AxialWithHessian};
use crate::error::{Error, Result, check_finite, check_len, check_output};
use crate::rest::RestShape;

/// Material and solver parameters of [`QuasistaticLayer`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct QuasistaticParams {
    /// `k_L` of the mesh-edge springs (N/m).
    pub stretch_stiffness: f64,
    /// `k_B` of the bending springs across hinges (N/m).
    pub bend_stiffness: f64,
    /// `k_A` of the axial zero-length springs (N/m).
    pub axial_stiffness: f64,
    /// `k_Z`: the zero-length spring to `r̂` of a vertex of mean mass has stiffness
    /// `μ k_Z` (N/m).
    pub zero_length_stiffness: f64,
    /// Newton stops when the largest residual force is below
    /// `tolerance · k_L · (mean rest edge length)`.
    pub tolerance: f64,
    pub max_iterations: usize,
    /// How Newton's linear systems are solved.
    pub solver: QuasistaticSolver,
    /// How the backward pass solves the adjoint system (Cholesky solver only).
    pub adjoint: QuasistaticAdjoint,
}

/// How the Cholesky path prepares the adjoint solve `H(r*) η = ∂E/∂r*` (Eq. 14).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum QuasistaticAdjoint {
    /// Keep Newton's last factor of the true Hessian (a step or more before `r*`) and
    /// solve by CG on `H(r*)` preconditioned with it; factorise `H(r*)` only where there
    /// is no such factor or CG fails. A saddle is then refused by the backward pass
    /// unless the forward pass already saw it.
    #[default]
    NewtonFactor,
    /// Factorise `H(r*)` in the forward pass (one more factorisation, the behaviour
    /// before issue 34): every forward pass refuses a saddle itself.
    FactorizeAtSolution,
}

/// The linear solver inside the quasistatic layer's Newton iterations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum QuasistaticSolver {
    /// Sparse Cholesky of every Newton matrix (weft-sim's `NewtonSolver`, factorisations
    /// reused while they contract the residual); the backward pass's adjoint solve as
    /// [`QuasistaticAdjoint`] says.
    #[default]
    Cholesky,
    /// Truncated Newton with block-Jacobi preconditioned conjugate gradients
    /// (`crate::krylov`, Geng et al. §5); no factorisation in the forward pass — the
    /// backward pass factorises the Hessian at `r*` when it is called.
    NewtonKrylov,
}

impl Default for QuasistaticParams {
    fn default() -> Self {
        Self {
            stretch_stiffness: 1.0,
            bend_stiffness: 0.1,
            axial_stiffness: 0.1,
            zero_length_stiffness: 1.0,
            tolerance: 1e-8,
            max_iterations: 100,
            solver: QuasistaticSolver::Cholesky,
            adjoint: QuasistaticAdjoint::NewtonFactor,
        }
    }
}

/// The scaling `μ` of the zero-length springs to the prediction (Geng et al. §6.2).
#[derive(Debug, Clone, PartialEq)]
pub enum ZeroLengthScaling {
    /// One `μ` for every vertex.
    Global(f64),
    /// `μ_i` per vertex.
    PerVertex(Vec<f64>),
}

impl ZeroLengthScaling {
    fn per_vertex(&self, n: usize) -> Result<Vec<f64>> {
        let mu = match self {
            Self::Global(mu) => {
                if !(mu.is_finite() && *mu > 0.0) {
                    return Err(Error::InvalidParameter {
                        name: "mu",
                        value: *mu,
                        reason: "must be positive and finite",
                    });
                }
                vec![*mu; n]
            }
            Self::PerVertex(mu) => {
                check_len("per-vertex mu", mu, n)?;
                check_finite("per-vertex mu", mu)?;
                if let Some(&bad) = mu.iter().find(|m| **m < 0.0) {
                    return Err(Error::InvalidParameter {
                        name: "mu_i",
                        value: bad,
                        reason: "must be ≥ 0",
                    });
                }
                if !mu.iter().any(|m| *m > 0.0) {
                    return Err(Error::InvalidParameter {
                        name: "mu_i",
                        value: 0.0,
                        reason: "at least one must be > 0",
                    });
                }
                mu.clone()
            }
        };
        Ok(mu)
    }
}

/// What one forward solve did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct QuasistaticReport {
    /// Both Newton phases together: iterations, residuals (N), energy (J), line-search
    /// halvings, diagonal shifts.
    pub newton: NewtonReport,
    /// Conjugate-gradient iterations over all Newton steps (Newton–Krylov only).
    pub cg_iterations: usize,
    /// Wall time of the forward pass, including the adjoint factorisation when the
    /// Cholesky path makes it (s).
    pub time_seconds: f64,
}

/// The result of [`QuasistaticLayer::forward`]: `r*` and what the backward pass needs.
#[derive(Debug, Clone)]
pub struct QuasistaticSolution {
    positions: Vec<f64>,
    prediction: Vec<f64>,
    mu: Vec<f64>,
    /// What the backward pass solves the adjoint system with.
    adjoint: Adjoint,
}

/// How the backward pass solves the adjoint system `H(r*) η = ∂E/∂r*` (Eq. 14).
#[derive(Debug, Clone)]
enum Adjoint {
    /// The Cholesky factor of the true Hessian at `r*`: one solve.
    Exact(CholeskyFactor),
    /// The factor of the true, unshifted Hessian at Newton's last freshly factorised
    /// iterate, a step or more before `r*`: CG on `H(r*)` preconditioned with it
    /// ([`ADJOINT_CG_TOLERANCE`]), the exact factorisation only if CG fails.
    NearbyFactor(CholeskyFactor),
    /// Nothing (the Newton–Krylov path): factorise `H(r*)` in the backward pass.
    Factorize,
}

/// Relative residual `‖g − Hη‖ / ‖g‖` at which the adjoint CG stops: the gradient is
/// then as exact as the factorised solve's to about `κ(H) · 1e-12`, far below the f32
/// network that consumes it.
const ADJOINT_CG_TOLERANCE: f64 = 1e-12;
/// CG iterations allowed before the adjoint falls back to factorising `H(r*)`: with a
/// factor from one Newton step away the preconditioned matrix is `I + O(‖x − r*‖)`, and
/// CG needs a handful.
const ADJOINT_CG_MAX_ITERATIONS: usize = 20;

impl QuasistaticSolution {
    /// Equilibrium positions `r*`, flat, vertex order of the input.
    pub fn positions(&self) -> &[f64] {
        &self.positions
    }
    pub fn into_positions(self) -> Vec<f64> {
        self.positions
    }
}

/// Gradients of a loss with respect to the layer's inputs.
#[derive(Debug, Clone, PartialEq)]
pub struct QuasistaticGradient {
    /// `∂E/∂r̂` (Eq. 14), flat like the prediction.
    pub pred: Vec<f64>,
    /// `∂E/∂μ_i` per vertex (Eq. 16 with per-vertex `μ_i`).
    pub mu_per_vertex: Vec<f64>,
    /// `∂E/∂μ` for a global `μ`: the sum of `mu_per_vertex`.
    pub mu: f64,
}

/// Geng et al.'s quasistatic projection as a layer: built once per rest mesh.
#[derive(Debug)]
pub struct QuasistaticLayer {
    rest: RestShape,
    params: QuasistaticParams,
    edge: Springs,
    bending: Springs,
    axial: AxialSprings,
    newton: NewtonSettings,
    /// Newton solvers (pattern and symbolic Cholesky built) idle between calls.
    pool: Mutex<Vec<NewtonSolver>>,
    /// The Hessian pattern of all terms, for the Newton–Krylov path and the adjoint.
    pattern: Arc<SymmetricPattern>,
    /// The axial springs' constant Hessian on `pattern`.
    axial_hessian: SymmetricMatrix,
}

impl QuasistaticLayer {
    pub fn new(rest: &TriMesh, params: QuasistaticParams) -> Result<Self> {
        for (name, value) in [
            ("stretch_stiffness", params.stretch_stiffness),
            ("zero_length_stiffness", params.zero_length_stiffness),
            ("tolerance", params.tolerance),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(Error::InvalidParameter {
                    name,
                    value,
                    reason: "must be positive and finite",
                });
            }
        }
        for (name, value) in [
            ("bend_stiffness", params.bend_stiffness),
            ("axial_stiffness", params.axial_stiffness),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(Error::InvalidParameter {
                    name,
                    value,
                    reason: "must be finite and ≥ 0",
                });
            }
        }
        let rest = RestShape::new(rest)?;
        let edge = Springs::at_rest(
            "edge springs",
            rest.rest_positions(),
            rest.edges().to_vec(),
            params.stretch_stiffness,
        )?;
        let bend_pairs = rest
            .topology()
            .hinges
            .iter()
            .filter(|h| h.opposite[0] != h.opposite[1])
            .map(|h| h.opposite)
            .collect();
        let bending = Springs::at_rest(
            "bending springs",
            rest.rest_positions(),
            bend_pairs,
            params.bend_stiffness,
        )?;
        let axial = AxialSprings::new(&rest, params.axial_stiffness)?;
        let n = rest.num_vertices();
        let anchors = ZeroLengthSprings::new("zero-length springs to the prediction", vec![1.0; n], vec![0.0; 3 * n])?;
        let terms: [&dyn Energy; 4] = [&edge, &bending, &axial, &anchors];
        let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(
            n,
            weft_sim::energy::checked_pairs(3 * n, &terms)?,
        ));
        let mean_length = rest.rest_lengths().iter().sum::<f64>() / rest.rest_lengths().len() as f64;
        // Factorisations are reused across Newton steps while they keep contracting the
        // residual (Shamanskii): the factorisation is most of a step's cost, and near the
        // equilibrium the Hessian hardly changes between steps.
        let newton = NewtonSettings {
            tolerance: params.tolerance * params.stretch_stiffness * mean_length,
            max_iterations: params.max_iterations,
            reuse_factorization: true,
            ..NewtonSettings::default()
        };
        let axial_hessian = axial.hessian(pattern.clone());
        Ok(Self {
            rest,
            params,
            edge,
            bending,
            axial,
            newton,
            pool: Mutex::new(Vec::new()),
            pattern,
            axial_hessian,
        })
    }

    pub fn rest(&self) -> &RestShape {
        &self.rest
    }
    pub fn params(&self) -> &QuasistaticParams {
        &self.params
    }
    pub fn num_vertices(&self) -> usize {
        self.rest.num_vertices()
    }
    /// Counts of (edge, bending, axial) springs.
    pub fn spring_counts(&self) -> (usize, usize, usize) {
        (self.edge.pairs().len(), self.bending.pairs().len(), self.axial.len())
    }

    fn axial_with_hessian(&self) -> AxialWithHessian<'_> {
        AxialWithHessian {
            springs: &self.axial,
            hessian: &self.axial_hessian,
        }
    }

    /// Zero-length spring base stiffness `k_i = k_Z m_i / m̄` (N/m) per vertex.
    pub fn zero_length_base(&self) -> Vec<f64> {
        self.rest
            .weights()
            .iter()
            .map(|w| self.params.zero_length_stiffness * w)
            .collect()
    }

    /// The zero-length springs tying each vertex to its prediction, vertex i with stiffness
    /// μ_i k_i (the E_Z of Geng et al. §5; k_i from [`zero_length_base`](Self::zero_length_base)).
    fn anchors(&self, pred: &[f64], mu: &[f64]) -> Result<ZeroLengthSprings> {
        let weights: Vec<f64> = mu.iter().zip(self.zero_length_base()).map(|(m, k)| m * k).collect();
        Ok(ZeroLengthSprings::new(
            "zero-length springs to the prediction",
            weights,
            pred.to_vec(),
        )?)
    }

    /// Equilibrium of the spring cloth tied to the prediction `pred` (flat `3 V`
    /// coordinates) with zero-length scaling `mu` (Geng et al. §5), Newton started at
    /// `pred`.
    pub fn forward(&self, pred: &[f64], mu: &ZeroLengthScaling) -> Result<(QuasistaticSolution, QuasistaticReport)> {
        self.forward_from(pred, mu, None)
    }

    /// [`forward`](Self::forward) with Newton started at `start` instead of `pred` — in
    /// training, the example's previous equilibrium moved by the change of its
    /// prediction (a warm start). The minimiser does not depend on the start unless the
    /// problem has several minima.
    pub fn forward_from(
        &self,
        pred: &[f64],
        mu: &ZeroLengthScaling,
        start: Option<&[f64]>,
    ) -> Result<(QuasistaticSolution, QuasistaticReport)> {
        let started = Instant::now();
        self.rest.check_positions("prediction", pred)?;
        if let Some(s) = start {
            self.rest.check_positions("warm start", s)?;
        }
        let n = self.num_vertices();
        let mu = mu.per_vertex(n)?;
        let anchors = self.anchors(pred, &mu)?;
        let axial = self.axial_with_hessian();
        let terms: [&dyn Energy; 4] = [&self.edge, &self.bending, &axial, &anchors];
        let mut x = start.unwrap_or(pred).to_vec();
        let (newton, cg_iterations, (adjoint, shifts)) = match self.params.solver {
            QuasistaticSolver::Cholesky => {
                let (report, adjoint) = self.with_solver(&terms, |solver| {
                    let report = self.minimize(solver, &terms, &mut x)?;
                    // Eq. 14 needs the true Hessian at r*. Newton's last factor of it, a
                    // step or more before r*, preconditions CG on it in the backward pass;
                    // without one (a start that needed no true-Hessian step, or a shifted
                    // or projected last factor) factorise it here, which also tells a
                    // saddle from a minimum.
                    let last = solver.take_last_factor();
                    match last {
                        Some(f)
                            if !f.projected
                                && f.shifts == 0
                                && self.params.adjoint == QuasistaticAdjoint::NewtonFactor =>
                        {
                            Ok((report, Ok(f.factor)))
                        }
                        _ => {
                            let f = solver.factorize_at(&terms, &x, HessianProjection::Never)?;
                            Ok((report, Err((f.factor, f.shifts))))
                        }
                    }
                })?;
                let adjoint = match adjoint {
                    Ok(nearby) => (Adjoint::NearbyFactor(nearby), 0),
                    Err((exact, shifts)) => (Adjoint::Exact(exact), shifts),
                };
                (report, 0, adjoint)
            }
            QuasistaticSolver::NewtonKrylov => {
                let mut hessian = SymmetricMatrix::zeros(self.pattern.clone());
                let k = crate::krylov::minimize(
                    &terms,
                    &mut hessian,
                    &mut x,
                    self.newton.tolerance,
                    self.newton.max_iterations,
                    self.newton.tolerance / self.params.tolerance,
                )?;
                let report = NewtonReport {
                    iterations: k.newton_iterations,
                    residual: k.residual,
                    initial_residual: k.initial_residual,
                    energy: k.energy,
                    line_search_halvings: k.line_search_halvings,
                    regularizations: 0,
                    factorizations: 0,
                    time: started.elapsed(),
                    residual_history: k.residual_history,
                    shift_history: Vec::new(),
                    residual_floor: 0.0,
                    cg_iterations: k.cg_iterations,
                    rejected_steps: 0,
                    fallback: None,
                    exact_from_iteration: None,
                    stopped_at_budget: false,
                };
                (report, k.cg_iterations, (Adjoint::Factorize, 0))
            }
        };
        check_output("quasistatic positions", &x)?;
        // A spring whose ends coincide exerts no force (its direction is undefined), so a
        // collapsed configuration is stationary although it is an energy maximum along
        // every spring: Newton would report it as converged.
        let collapsed: Vec<usize> = (0..self.edge.pairs().len())
            .filter(|&s| {
                let [a, b] = self.edge.pairs()[s];
                let l = (0..3)
                    .map(|k| (x[3 * a + k] - x[3 * b + k]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                l <= 1e-9 * self.edge.rest_lengths()[s]
            })
            .collect();
        if let Some(&first) = collapsed.first() {
            return Err(Error::CollapsedSprings {
                count: collapsed.len(),
                first,
            });
        }
        // The adjoint solve (Eq. 14) needs the true Hessian at r*; an indefinite one means
        // r* is a saddle, and a shifted matrix would give the gradient of another problem.
        if shifts > 0 {
            return Err(Error::NotAMinimum { shifts });
        }
        let report = QuasistaticReport {
            newton,
            cg_iterations,
            time_seconds: started.elapsed().as_secs_f64(),
        };
        Ok((
            QuasistaticSolution {
                positions: x,
                prediction: pred.to_vec(),
                mu,
                adjoint,
            },
            report,
        ))
    }

    /// Runs `f` with a pooled Newton solver (pattern and symbolic Cholesky built once).
    fn with_solver<T>(
        &self,
        terms: &[&dyn Energy],
        f: impl FnOnce(&mut NewtonSolver) -> weft_sim::Result<T>,
    ) -> Result<T> {
        let pooled = self.pool.lock().ok().and_then(|mut p| p.pop());
        let mut solver = match pooled {
            Some(s) => s,
            None => NewtonSolver::new(3 * self.num_vertices(), terms, vec![false; 3 * self.num_vertices()])?,
        };
        let result = f(&mut solver);
        if let Ok(mut pool) = self.pool.lock() {
            pool.push(solver);
        }
        Ok(result?)
    }

    /// Newton in two phases: with per-spring PSD projection (the definiteness fix of
    /// Teran et al. 2005) until the residual force is within `10⁴ ×` the tolerance — far
    /// from equilibrium, e.g. from an inverted or badly stretched prediction — then with
    /// the true Hessian (diagonally shifted by weft-sim's solver only if indefinite), whose
    /// convergence stays quadratic where compressed springs make the projection differ
    /// from the true Hessian at the minimum. The first phase also switches to the true
    /// Hessian once its residual has risen on two projected steps in a row (as the drape
    /// ground truth does, `DrapeParams::exact_hessian_after_rises`): on a loose garment at
    /// small μ the projected steps otherwise crawl for tens of iterations short of the
    /// hand-over, and can stall there (docs/BENCHMARKS.md, "The quasistatic layer on the
    /// loose sleeve").
    fn minimize(
        &self,
        solver: &mut NewtonSolver,
        terms: &[&dyn Energy],
        x: &mut [f64],
    ) -> weft_sim::Result<weft_sim::NewtonReport> {
        let coarse = NewtonSettings {
            tolerance: 1e4 * self.newton.tolerance,
            exact_hessian_after_rises: Some(2),
            ..self.newton
        };
        let first = solver.minimize(terms, x, &coarse)?;
        let fine = NewtonSettings {
            projection: HessianProjection::Never,
            max_iterations: self.newton.max_iterations.saturating_sub(first.iterations).max(1),
            ..self.newton
        };
        let second = solver.minimize(terms, x, &fine)?;
        let mut history = first.residual_history;
        history.extend(&second.residual_history);
        let mut shifts = first.shift_history;
        shifts.extend(&second.shift_history);
        Ok(weft_sim::NewtonReport {
            iterations: first.iterations + second.iterations,
            initial_residual: first.initial_residual,
            line_search_halvings: first.line_search_halvings + second.line_search_halvings,
            regularizations: first.regularizations + second.regularizations,
            factorizations: first.factorizations + second.factorizations,
            time: first.time + second.time,
            residual_history: history,
            shift_history: shifts,
            cg_iterations: first.cg_iterations + second.cg_iterations,
            rejected_steps: first.rejected_steps + second.rejected_steps,
            ..second
        })
    }

    /// `∂E/∂r̂` and `∂E/∂μ` from `∂E/∂r*` (`grad_out`) by one adjoint solve (Eq. 14, 16).
    pub fn backward(&self, solution: &QuasistaticSolution, grad_out: &[f64]) -> Result<QuasistaticGradient> {
        self.rest.check_positions("output gradient", grad_out)?;
        let n = self.num_vertices();
        let factor_dim = match &solution.adjoint {
            Adjoint::Exact(f) | Adjoint::NearbyFactor(f) => f.dim(),
            Adjoint::Factorize => 3 * n,
        };
        if solution.positions.len() != 3 * n || factor_dim != 3 * n {
            return Err(Error::LengthMismatch {
                what: "forward state",
                expected: 3 * n,
                got: solution.positions.len(),
            });
        }
        let mut eta = grad_out.to_vec();
        if let Adjoint::Exact(f) = &solution.adjoint {
            f.solve_in_place(&mut eta);
        } else {
            let anchors = self.anchors(&solution.prediction, &solution.mu)?;
            let axial = self.axial_with_hessian();
            let terms: [&dyn Energy; 4] = [&self.edge, &self.bending, &axial, &anchors];
            let solved = match &solution.adjoint {
                Adjoint::NearbyFactor(f) => {
                    let mut h = SymmetricMatrix::zeros(self.pattern.clone());
                    for t in terms {
                        t.add_hessian(&solution.positions, false, &mut h);
                    }
                    let precondition = |r: &[f64], z: &mut [f64]| {
                        z.copy_from_slice(r);
                        f.solve_in_place(z);
                    };
                    let out = weft_linalg::pcg(
                        &h,
                        precondition,
                        grad_out,
                        &mut eta,
                        ADJOINT_CG_TOLERANCE,
                        ADJOINT_CG_MAX_ITERATIONS,
                    );
                    out.converged
                }
                _ => false,
            };
            if !solved {
                // No factor at r* (the Newton–Krylov path), or CG with the nearby one did
                // not converge: factorise the true Hessian at r* now (Eq. 14), refusing a
                // saddle as the forward pass does.
                let at_solution = self.with_solver(&terms, |solver| {
                    solver.factorize_at(&terms, &solution.positions, HessianProjection::Never)
                })?;
                if at_solution.shifts > 0 {
                    return Err(Error::NotAMinimum {
                        shifts: at_solution.shifts,
                    });
                }
                eta.copy_from_slice(grad_out);
                at_solution.factor.solve_in_place(&mut eta);
            }
        }
        let base = self.zero_length_base();
        let pred: Vec<f64> = (0..3 * n).map(|i| solution.mu[i / 3] * base[i / 3] * eta[i]).collect();
        let mu_per_vertex: Vec<f64> = (0..n)
            .map(|v| {
                base[v]
                    * (0..3)
                        .map(|c| eta[3 * v + c] * (solution.prediction[3 * v + c] - solution.positions[3 * v + c]))
                        .sum::<f64>()
            })
            .collect();
        check_output("quasistatic backward gradient", &pred)?;
        check_output("quasistatic backward mu gradient", &mu_per_vertex)?;
        let mu = mu_per_vertex.iter().sum();
        Ok(QuasistaticGradient {
            pred,
            mu_per_vertex,
            mu,
        })
    }

    /// [`forward`](Self::forward) over many predictions in parallel (rayon over examples).
    pub fn forward_batch<P: AsRef<[f64]> + Sync>(
        &self,
        preds: &[P],
        mu: &ZeroLengthScaling,
    ) -> Vec<Result<(QuasistaticSolution, QuasistaticReport)>> {
        preds.par_iter().map(|p| self.forward(p.as_ref(), mu)).collect()
    }

    /// [`forward_from`](Self::forward_from) over many predictions in parallel, Newton for
    /// example `b` started at `starts[b]` where there is one (a warm start) and at its
    /// prediction otherwise; `starts` of another length makes every entry an error.
    pub fn forward_batch_from<P: AsRef<[f64]> + Sync, S: AsRef<[f64]> + Sync>(
        &self,
        preds: &[P],
        mu: &ZeroLengthScaling,
        starts: &[Option<S>],
    ) -> Vec<Result<(QuasistaticSolution, QuasistaticReport)>> {
        crate::batch::forward_batch_from(preds, starts, |p, s| self.forward_from(p, mu, s.map(AsRef::as_ref)))
    }

    /// [`backward`](Self::backward) over many examples in parallel.
    pub fn backward_batch<G: AsRef<[f64]> + Sync>(
        &self,
        solutions: &[QuasistaticSolution],
        grads: &[G],
    ) -> Result<Vec<QuasistaticGradient>> {
        crate::batch::backward_batch(solutions, grads, |s, g| self.backward(s, g))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use weft_testkit::{TestRng, max_norm_rel_error};

    #[test]
    fn the_adjoint_by_cg_with_newtons_last_factor_matches_the_factorised_one() {
        // A stretched, noisy prediction of a 9 × 9 sheet: Newton takes true-Hessian steps,
        // so the forward pass keeps the last factor, and the backward pass through it must
        // give the gradient the factorisation at r* gives, to the CG tolerance.
        let rest = weft_mesh::generators::sheet(9, 1.0).unwrap();
        let layer = QuasistaticLayer::new(&rest, QuasistaticParams::default()).unwrap();
        let factorizing = QuasistaticLayer::new(
            &rest,
            QuasistaticParams {
                adjoint: QuasistaticAdjoint::FactorizeAtSolution,
                ..QuasistaticParams::default()
            },
        )
        .unwrap();
        let mut rng = TestRng::new(5);
        let pred: Vec<f64> = rest
            .flat_positions()
            .iter()
            .map(|x| 1.15 * x + rng.uniform(-0.01, 0.01))
            .collect();
        for mu in [ZeroLengthScaling::Global(0.1), ZeroLengthScaling::Global(1.0)] {
            let (sol, _) = layer.forward(&pred, &mu).unwrap();
            assert!(matches!(sol.adjoint, Adjoint::NearbyFactor(_)), "{:?}", sol.adjoint);
            let g = rng.vec(pred.len(), -1.0, 1.0);
            let by_cg = layer.backward(&sol, &g).unwrap();
            let exact = QuasistaticSolution {
                adjoint: Adjoint::Factorize,
                ..sol.clone()
            };
            let by_factor = layer.backward(&exact, &g).unwrap();
            // The option that factorises in the forward pass: the same r* and gradient.
            let (eager, _) = factorizing.forward(&pred, &mu).unwrap();
            assert!(matches!(eager.adjoint, Adjoint::Exact(_)));
            assert_eq!(eager.positions, sol.positions);
            let by_eager = factorizing.backward(&eager, &g).unwrap();
            assert!(max_norm_rel_error(&by_eager.pred, &by_factor.pred) < 1e-12);
            let err = max_norm_rel_error(&by_cg.pred, &by_factor.pred);
            assert!(err < 1e-9, "∂E/∂r̂: CG against the factor at r*: {err:e}");
            let err_mu = max_norm_rel_error(&by_cg.mu_per_vertex, &by_factor.mu_per_vertex);
            assert!(err_mu < 1e-8, "∂E/∂μ_i: {err_mu:e}");
            // A zero output gradient gives zero input gradients.
            let zero = layer.backward(&sol, &vec![0.0; pred.len()]).unwrap();
            assert!(zero.pred.iter().chain(&zero.mu_per_vertex).all(|v| *v == 0.0));
        }
    }
}
