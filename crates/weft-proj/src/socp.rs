//! The inextensibility layer (Geng et al. §3–4): project a predicted configuration `r̂`
//! onto edge-length bounds, and differentiate the projection.
//!
//! # Forward (Geng et al. Eq. 1)
//!
//! `min_r Σ_i ½ k_i ‖r_i − r̂_i‖²  s.t.  ‖r_a − r_b‖ ≤ (1 + ε) l̄_e  ∀ e`, with `k_i` the
//! rest mesh's lumped vertex masses (normalised to mean 1; only their ratios matter).
//!
//! Geng et al. Eq. 3 moves the objective into one large cone `Q^{3n+1}`. Interior-point
//! methods for quadratic cone programs take a quadratic objective directly, so we keep it
//! quadratic and solve for the displacement `δ = r − r̂` in units of the mean rest length
//! `ℓ` (translation- and scale-invariant):
//!
//! ```text
//! min_δ ½ δᵀ K δ   s.t.   s_e = b_e − A_e δ ∈ Q⁴,   b_e = [l_e^max; r̂_a − r̂_b] / ℓ,
//!                                                     A_e δ = [0; −(δ_a − δ_b)]
//! ```
//!
//! so `s_e = [l_e^max; r_a − r_b] / ℓ` exactly as Geng's `s_e` (Eq. 3), and `r̂` enters
//! only through `b`.
//!
//! By default the primal–dual interior-point method of `crate::ipm` solves it: Nesterov–
//! Todd scaling, Mehrotra's predictor–corrector, and per iteration one sparse Cholesky
//! of the reduced `3V × 3V` matrix `K + Σ_e D_eᵀ G_e D_e` (the mesh-edge sparsity).
//! Clarabel on the full conic KKT system is kept as [`ConicSolver::Clarabel`] for
//! cross-checks. Both return `(x, s, z)` with the same conventions. The polish (Newton on
//! the active-set conditions, Eq. 2) then makes the KKT conditions hold to round-off;
//! with the reduced IPM it is first tried from an iterate within
//! [`SocpSettings::early_polish_gap`], whose certificate ends the solve.
//!
//! # Backward (Geng et al. Eq. 6–11, our formulation)
//!
//! The optimality conditions are `Kδ + Aᵀz = 0`, `Aδ + s = b`, `s, z ∈ K`,
//! `s ∘ z = 0`. Differentiating (Eq. 7) and writing `dr = dr̂ + dδ`:
//!
//! ```text
//! K dr + Σ_e A_eᵀ dz_e = K dr̂,   ds_e = [0; D_e dr],   S_e dz_e + Z_e ds_e = 0
//! ```
//!
//! with `D_e = E_a − E_b` and `S_e`, `Z_e` the arrow matrices of Eq. 9. Since `A_e` has
//! a zero first row, `dz_e⁰` appears only in the complementarity rows; those give
//! `dz_e¹ = −(s_e¹ dz_e⁰ + z_e⁰ D_e dr)/s_e⁰` and
//! `γ_e dz_e⁰ = (z_e⁰ s_e¹/s_e⁰ − z_e¹)ᵀ D_e dr` with `γ_e = (s_e⁰² − ‖s_e¹‖²)/s_e⁰`.
//! Geng's symmetrisation (Eq. 10) uses the optimality condition `s⁰z¹ + z⁰s¹ = 0`
//! (the vector part of `s ∘ z`, zero on the whole central path) to replace
//! `z⁰s¹/s⁰ − z¹` by `2 z⁰ v_e`, `v_e = s_e¹/s_e⁰`. Dividing that row by `2z⁰` gives
//! one symmetric quasi-definite system per solution:
//!
//! ```text
//! ⎡ K + Σ_e (z_e⁰/s_e⁰) D_eᵀD_e    D_eᵀ v_e        ⎤ ⎡ dr    ⎤   ⎡ K dr̂ ⎤
//! ⎣ v_eᵀ D_e                       −γ_e / (2 z_e⁰) ⎦ ⎣ dz_e⁰ ⎦ = ⎣ 0    ⎦
//! ```
//!
//! At an active edge (`γ_e → 0`) the second row is the linearised constraint
//! `u_eᵀ (dr_a − dr_b) = 0`; at an inactive one (`z_e⁰ → 0`) it decouples. An edge whose
//! row would be nearly decoupled (`2z⁰/γ ≤ k̄`) is eliminated exactly instead (its Schur
//! complement `(2z⁰/γ) D_eᵀ v_e v_eᵀ D_e` is added to the primal block) so the matrix
//! stays well scaled. The backward pass is Eq. 11: solve `𝒦 [η; ν] = [∂E/∂r*; 0]` once
//! with a regularised sparse LDLᵀ, then `∂E/∂r̂ = K η`. The LDLᵀ orders every constraint
//! row first (`crate::kkt`): `1 × 1` row pivots, regularised sign-aware to `≤ −δ`, then
//! the Cholesky factor of their Schur complement, which has the mesh-edge sparsity; after
//! the polish only the active edges carry force, and the factorisation runs over their
//! pattern, the one the polish already analysed.
//!
//! The null space of Appendix A (e.g. three collinear, maximally stretched edges,
//! Fig. 11) lies entirely in the multipliers `dz⁰`: the primal block is positive definite,
//! so `dr` (and `η`) is unique. The `−γ/(2z⁰)` diagonal left by the interior-point
//! solution and the LDLᵀ's sign-aware regularisation pick one multiplier solution;
//! iterative refinement against the unregularised matrix then restores `η`.

use std::sync::Arc;
use std::time::Instant;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT, SupportedConeT::SecondOrderConeT,
};
use rayon::prelude::*;
use weft_mesh::TriMesh;

use crate::error::{Error, Result, check_output};
use crate::ipm::{IpmSettings, ReducedIpm};
use crate::kkt::{EdgeBlock, EdgeSystem, KktFactor};
use crate::rest::{RestShape, edge_vector};

/// Which interior-point method solves the forward SOCP.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ConicSolver {
    /// Our primal–dual method on the reduced `3V × 3V` normal equations (`crate::ipm`):
    /// one sparse Cholesky of a mesh-edge-sparse matrix per iteration.
    #[default]
    ReducedIpm,
    /// Clarabel on the full conic KKT system (QDLDL); kept for cross-checking.
    Clarabel,
}

/// Settings of [`InextensibilityLayer`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SocpSettings {
    pub solver: ConicSolver,
    /// The interior-point tolerance on the relative primal and dual residuals and the
    /// relative gap (for Clarabel: its absolute and relative gap and feasibility
    /// tolerances).
    pub tolerance: f64,
    pub max_iterations: u32,
    /// Largest accepted relative excess of an edge over its bound: `l/l^max − 1`.
    pub feasibility_tolerance: f64,
    /// Regularisation of the polish and backward LDLᵀ (a constraint-row pivot above
    /// `−δ` becomes `−δ`) and its steps of iterative refinement against the
    /// unregularised matrix.
    pub ldlt_delta: f64,
    pub refinement_steps: usize,
    /// Iterative refinement of the interior-point method's linear solves: for the
    /// reduced IPM a residual check per solve and one refinement step when it is above
    /// `√ε`; for Clarabel its own refinement (about 25 % of its time on the paper-sized
    /// sheet). On by default for accuracy on degenerate problems.
    pub iterative_refinement: bool,
    /// Print the interior-point iteration log.
    pub verbose: bool,
    /// Polish the interior-point solution by Newton's method on the active-set KKT
    /// conditions (Eq. 2), so they hold to round-off.
    pub polish: bool,
    /// With the polish on and the reduced IPM, the polish is first tried from the first
    /// iterate whose relative gap and residuals are below this value. An accepted polish
    /// satisfies the KKT conditions to round-off with non-negative multipliers and every
    /// bound held, which certifies the (unique) optimum, and ends the solve; a rejected
    /// one lets the interior-point method continue to `tolerance`. `0` turns the early
    /// try off.
    pub early_polish_gap: f64,
}

impl Default for SocpSettings {
    fn default() -> Self {
        Self {
            solver: ConicSolver::default(),
            tolerance: 1e-8,
            max_iterations: 100,
            feasibility_tolerance: 1e-6,
            ldlt_delta: 1e-9,
            refinement_steps: 3,
            iterative_refinement: true,
            verbose: false,
            polish: true,
            early_polish_gap: 1e-3,
        }
    }
}

impl SocpSettings {
    /// Tight tolerances (1e-10) for finite-difference checks of the backward pass.
    pub fn tight() -> Self {
        Self {
            tolerance: 1e-10,
            ..Self::default()
        }
    }
}

/// What one forward solve did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SocpReport {
    /// The interior-point method's final status (`Solved`, or Clarabel's `AlmostSolved`).
    /// With an accepted early polish the reduced IPM reports `Solved` at the iterate it
    /// handed over (see [`SocpSettings::early_polish_gap`]).
    pub status: String,
    /// Interior-point iterations of whichever [`ConicSolver`] ran.
    pub iterations: u32,
    /// Newton iterations of the active-set polish, `None` if it was off or rejected (the
    /// interior-point solution is returned then).
    pub polish_iterations: Option<usize>,
    /// Wall time of the whole forward pass, including the conic solve (s).
    pub time_seconds: f64,
    /// The interior-point method's own solve time (s).
    pub solver_seconds: f64,
    /// Time in the polish (s), including an early attempt that was rejected.
    pub polish_seconds: f64,
    /// The interior-point method's primal and dual residuals.
    pub primal_residual: f64,
    pub dual_residual: f64,
    /// Relative KKT residual at the returned point: the largest of stationarity
    /// `‖Kδ + Aᵀz‖∞ / max(‖Kδ‖∞, ‖Aᵀz‖∞)`, relative complementarity `max_e s_eᵀz_e /
    /// (s_e⁰ z_e⁰)` over edges carrying force, and constraint violation.
    pub kkt_residual: f64,
    /// `max_e (l_e / l_e^max − 1)`: ≤ 0 when every bound holds.
    pub max_violation: f64,
    /// Edges at their bound (relative slack below 1e-6).
    pub active_constraints: usize,
    pub num_constraints: usize,
}

/// The result of [`InextensibilityLayer::forward`]: the projected positions and what
/// the backward pass needs (the conic solution `s`, `z` in solver units).
#[derive(Debug, Clone)]
pub struct SocpSolution {
    positions: Vec<f64>,
    s: Vec<f64>,
    z: Vec<f64>,
    /// The polish's system over its active edges, reused by the backward pass.
    active_system: Option<Arc<EdgeSystem>>,
}

impl SocpSolution {
    /// Projected positions `r*`, flat `[x0, y0, z0, …]`, vertex order of the input.
    pub fn positions(&self) -> &[f64] {
        &self.positions
    }
    pub fn into_positions(self) -> Vec<f64> {
        self.positions
    }
}

/// A conic solution `(x, s, z)` of either [`ConicSolver`] and what it took.
#[derive(Debug)]
struct ConicSolution {
    x: Vec<f64>,
    s: Vec<f64>,
    z: Vec<f64>,
    status: String,
    iterations: u32,
    seconds: f64,
    primal_residual: f64,
    dual_residual: f64,
}

/// A solution certified by the polish: the active-set KKT conditions hold to round-off.
#[derive(Debug)]
struct Polished {
    x: Vec<f64>,
    s: Vec<f64>,
    z: Vec<f64>,
    iterations: usize,
    /// The edge system over the final active set, kept for the backward pass.
    system: Arc<EdgeSystem>,
}

/// What one backward solve did.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct BackwardReport {
    pub time_seconds: f64,
    /// Relative residual of the LDLᵀ solve after refinement.
    pub linear_residual: f64,
    /// Edges kept as constraint rows in the differentiated KKT system.
    pub constraint_rows: usize,
}

/// Geng et al.'s inextensibility projection as a layer: built once per rest mesh and
/// `ε`, then [`forward`](Self::forward) / [`backward`](Self::backward) per example.
#[derive(Debug)]
pub struct InextensibilityLayer {
    rest: RestShape,
    epsilon: f64,
    settings: SocpSettings,
    /// Mean rest length `ℓ`: the solver works in units of `ℓ`.
    length_scale: f64,
    max_lengths: Vec<f64>,
    p: CscMatrix<f64>,
    a: CscMatrix<f64>,
    cones: Vec<SupportedConeT<f64>>,
    /// `K + Σ_e D_eᵀ G_e D_e` and its symbolic Cholesky factor: the linear algebra of
    /// the interior-point method, the polish and the backward pass.
    system: Arc<EdgeSystem>,
}

impl InextensibilityLayer {
    /// Builds the layer for the rest mesh `rest` and strain bound `epsilon ≥ 0`.
    pub fn new(rest: &TriMesh, epsilon: f64, settings: SocpSettings) -> Result<Self> {
        if !(epsilon.is_finite() && epsilon >= 0.0) {
            return Err(Error::InvalidParameter {
                name: "epsilon",
                value: epsilon,
                reason: "must be finite and ≥ 0",
            });
        }
        if !(settings.early_polish_gap.is_finite() && settings.early_polish_gap >= 0.0) {
            return Err(Error::InvalidParameter {
                name: "early_polish_gap",
                value: settings.early_polish_gap,
                reason: "must be finite and ≥ 0",
            });
        }
        for (name, value) in [
            ("tolerance", settings.tolerance),
            ("feasibility_tolerance", settings.feasibility_tolerance),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(Error::InvalidParameter {
                    name,
                    value,
                    reason: "must be positive and finite",
                });
            }
        }
        let rest = RestShape::new(rest)?;
        let nv = rest.num_vertices();
        let edges = rest.edges().to_vec();
        let m = edges.len();
        let length_scale = rest.rest_lengths().iter().sum::<f64>() / m as f64;
        let max_lengths: Vec<f64> = rest.rest_lengths().iter().map(|l| (1.0 + epsilon) * l).collect();

        // P = K (diagonal, upper triangle trivially).
        let n = 3 * nv;
        let kdiag: Vec<f64> = (0..n).map(|i| rest.weights()[i / 3]).collect();
        let p = CscMatrix::new(n, n, (0..=n).collect(), (0..n).collect(), kdiag);
        // A: rows 4e+1+c hold −1 at (a, c) and +1 at (b, c); row 4e is empty (s_e⁰ = b_e⁰).
        let (mut ri, mut ci, mut vals) = (
            Vec::with_capacity(6 * m),
            Vec::with_capacity(6 * m),
            Vec::with_capacity(6 * m),
        );
        for (e, &[va, vb]) in edges.iter().enumerate() {
            for c in 0..3 {
                ri.extend([4 * e + 1 + c, 4 * e + 1 + c]);
                ci.extend([3 * va + c, 3 * vb + c]);
                vals.extend([-1.0, 1.0]);
            }
        }
        let a = CscMatrix::new_from_triplets(4 * m, n, ri, ci, vals);
        let cones = vec![SecondOrderConeT(4); m];

        let system = Arc::new(EdgeSystem::new(nv, &edges, rest.weights())?);
        Ok(Self {
            rest,
            epsilon,
            settings,
            length_scale,
            max_lengths,
            p,
            a,
            cones,
            system,
        })
    }

    pub fn rest(&self) -> &RestShape {
        &self.rest
    }
    pub fn epsilon(&self) -> f64 {
        self.epsilon
    }
    pub fn settings(&self) -> &SocpSettings {
        &self.settings
    }
    pub fn num_vertices(&self) -> usize {
        self.rest.num_vertices()
    }
    pub fn num_constraints(&self) -> usize {
        self.max_lengths.len()
    }
    /// The per-vertex weights `k_i` of the objective (lumped masses over their mean).
    pub fn weights(&self) -> &[f64] {
        self.rest.weights()
    }

    /// Solves the SOCP for `b` with Clarabel. A fresh solver per call keeps results
    /// independent of call order and thread.
    fn solve_clarabel(&self, b: &[f64]) -> Result<ConicSolution> {
        let tol = self.settings.tolerance;
        let settings = DefaultSettings {
            verbose: self.settings.verbose,
            iterative_refinement_enable: self.settings.iterative_refinement,
            max_iter: self.settings.max_iterations,
            tol_gap_abs: tol,
            tol_gap_rel: tol,
            tol_feas: tol,
            tol_ktratio: tol.min(1e-6),
            ..DefaultSettings::default()
        };
        let q = vec![0.0; 3 * self.num_vertices()];
        let mut solver = DefaultSolver::new(&self.p, &q, &self.a, b, &self.cones, settings)
            .map_err(|e| Error::SolverSetup(e.to_string()))?;
        solver.solve();
        let sol = &solver.solution;
        let status = format!("{:?}", sol.status);
        if !matches!(sol.status, SolverStatus::Solved | SolverStatus::AlmostSolved) {
            return Err(Error::SolverFailed {
                status,
                iterations: sol.iterations,
            });
        }
        Ok(ConicSolution {
            x: sol.x.clone(),
            s: sol.s.clone(),
            z: sol.z.clone(),
            status,
            iterations: sol.iterations,
            seconds: sol.solve_time,
            primal_residual: sol.r_prim,
            dual_residual: sol.r_dual,
        })
    }

    /// Solves the SOCP for `b` with the reduced-system interior-point method. With the
    /// polish on, its first iterate within `early_polish_gap` is polished; if the polish
    /// certifies the optimum there, that ends the solve (the seconds in the polish are
    /// returned apart from the interior-point time).
    fn solve_reduced_ipm(&self, b: &[f64]) -> Result<(ConicSolution, Option<Polished>, f64)> {
        let settings = IpmSettings {
            tolerance: self.settings.tolerance,
            max_iterations: self.settings.max_iterations,
            iterative_refinement: self.settings.iterative_refinement,
            verbose: self.settings.verbose,
            early_finish_gap: if self.settings.polish {
                self.settings.early_polish_gap
            } else {
                0.0
            },
        };
        let mut polish_seconds = 0.0;
        let (sol, polished) = ReducedIpm::new(&self.system).solve(b, &settings, |x, s, z| {
            let start = Instant::now();
            let polished = self.polish(b, x, s, z);
            polish_seconds += start.elapsed().as_secs_f64();
            polished
        })?;
        let conic = ConicSolution {
            x: sol.x,
            s: sol.s,
            z: sol.z,
            status: "Solved".to_string(),
            iterations: sol.iterations,
            seconds: sol.seconds - polish_seconds,
            primal_residual: sol.primal_residual,
            dual_residual: sol.dual_residual,
        };
        Ok((conic, polished, polish_seconds))
    }

    /// Projects the flat prediction `pred` (`3 V` coordinates, metres) onto the
    /// edge-length bounds (Geng et al. Eq. 1).
    pub fn forward(&self, pred: &[f64]) -> Result<(SocpSolution, SocpReport)> {
        let start = Instant::now();
        self.rest.check_positions("prediction", pred)?;
        let m = self.num_constraints();
        let ell = self.length_scale;
        let mut b = vec![0.0; 4 * m];
        for (e, &[va, vb]) in self.rest.edges().iter().enumerate() {
            let d = edge_vector(pred, va, vb) / ell;
            b[4 * e] = self.max_lengths[e] / ell;
            b[4 * e + 1..4 * e + 4].copy_from_slice(d.as_slice());
        }
        let (conic, early, mut polish_seconds) = match self.settings.solver {
            ConicSolver::ReducedIpm => self.solve_reduced_ipm(&b)?,
            ConicSolver::Clarabel => (self.solve_clarabel(&b)?, None, 0.0),
        };
        check_output("conic solution", &conic.x)?;
        check_output("conic slacks", &conic.s)?;
        check_output("conic duals", &conic.z)?;
        let polished = early.or_else(|| {
            let start = Instant::now();
            let polished = self
                .settings
                .polish
                .then(|| self.polish(&b, &conic.x, &conic.s, &conic.z))
                .flatten();
            polish_seconds += start.elapsed().as_secs_f64();
            polished
        });
        let (polish_iterations, active_system) = match &polished {
            Some(p) => (Some(p.iterations), Some(p.system.clone())),
            None => (None, None),
        };
        let (x, s, z) = match polished {
            Some(p) => (p.x, p.s, p.z),
            None => (conic.x, conic.s, conic.z),
        };

        let positions: Vec<f64> = pred.iter().zip(&x).map(|(p, d)| p + ell * d).collect();
        check_output("projected positions", &positions)?;
        let mut max_violation = f64::NEG_INFINITY;
        let mut worst = 0;
        let mut active = 0;
        for (e, &[va, vb]) in self.rest.edges().iter().enumerate() {
            let excess = edge_vector(&positions, va, vb).norm() / self.max_lengths[e] - 1.0;
            if excess > max_violation {
                max_violation = excess;
                worst = e;
            }
            if excess > -1e-6 {
                active += 1;
            }
        }
        if max_violation > self.settings.feasibility_tolerance {
            let ratio = (1.0 + max_violation) * (1.0 + self.epsilon);
            return Err(Error::ConstraintViolated {
                edge: worst,
                ratio,
                bound: 1.0 + self.epsilon,
            });
        }
        let (stationarity, complementarity) = self.kkt_residuals(&x, &s, &z);
        let report = SocpReport {
            status: conic.status,
            iterations: conic.iterations,
            polish_iterations,
            time_seconds: start.elapsed().as_secs_f64(),
            solver_seconds: conic.seconds,
            polish_seconds,
            primal_residual: conic.primal_residual,
            dual_residual: conic.dual_residual,
            kkt_residual: stationarity.max(complementarity).max(max_violation.max(0.0)),
            max_violation,
            active_constraints: active,
            num_constraints: m,
        };
        let solution = SocpSolution {
            positions,
            s,
            z,
            active_system,
        };
        Ok((solution, report))
    }

    /// Relative stationarity `‖Kδ + Aᵀz‖∞ / max(‖Kδ‖∞, ‖Aᵀz‖∞)` and relative
    /// complementarity `max_e |s_eᵀz_e| / (s_e⁰ max z⁰)` in solver units.
    fn kkt_residuals(&self, x: &[f64], s: &[f64], z: &[f64]) -> (f64, f64) {
        let w = self.rest.weights();
        let mut grad_obj: Vec<f64> = x.iter().enumerate().map(|(i, d)| w[i / 3] * d).collect();
        let mut at_z = vec![0.0; x.len()];
        let z0_max = (0..self.num_constraints()).map(|e| z[4 * e]).fold(0.0, f64::max);
        let mut complementarity: f64 = 0.0;
        for (e, &[va, vb]) in self.rest.edges().iter().enumerate() {
            for c in 0..3 {
                at_z[3 * va + c] -= z[4 * e + 1 + c];
                at_z[3 * vb + c] += z[4 * e + 1 + c];
            }
            let sz: f64 = (0..4).map(|k| s[4 * e + k] * z[4 * e + k]).sum();
            if z0_max > 0.0 {
                complementarity = complementarity.max(sz.abs() / (s[4 * e] * z0_max));
            }
        }
        let scale = weft_linalg::max_abs(grad_obj.iter().chain(&at_z).copied());
        grad_obj.iter_mut().zip(&at_z).for_each(|(g, a)| *g += a);
        let stationarity = if !scale.is_finite() {
            f64::INFINITY
        } else if scale > 0.0 {
            weft_linalg::max_abs(grad_obj.iter().copied()) / scale
        } else {
            0.0
        };
        (stationarity, complementarity)
    }

    /// Whether the conic pair `(s_e, z_e)` is kept as a constraint row: `2 z⁰ > γ`, i.e.
    /// eliminating it would add a stiffness `2z⁰/γ` above the mean weight `k̄ = 1`.
    fn is_active(s: &[f64], z: &[f64]) -> bool {
        Self::is_loaded_above(s, z, 1.0)
    }

    /// Whether `2 z⁰ > threshold · γ` (`γ = (s⁰² − ‖s¹‖²)/s⁰`) with `z⁰, s⁰ > 0`.
    fn is_loaded_above(s: &[f64], z: &[f64], threshold: f64) -> bool {
        let (s0, z0) = (s[0], z[0]);
        if !(z0 > 0.0 && s0 > 0.0) {
            return false;
        }
        let s1n = (s[1] * s[1] + s[2] * s[2] + s[3] * s[3]).sqrt();
        2.0 * z0 > threshold * ((s0 - s1n) * (s0 + s1n) / s0).max(0.0)
    }

    /// Polishes the interior-point solution: Newton's method on the KKT conditions of
    /// Eq. 2 restricted to the active edges (`‖d_e‖ = l_e^max`), so the returned point
    /// satisfies them to round-off rather than to the interior-point tolerance.
    /// Accepted only if it converges with non-negative multipliers and every other edge
    /// within its bound; returns the polished point, or `None` if it was rejected.
    fn polish(&self, b: &[f64], x: &[f64], s: &[f64], z: &[f64]) -> Option<Polished> {
        let m = self.num_constraints();
        let edges = self.rest.edges();
        let d_at = |delta: &[f64], e: usize| {
            let [va, vb] = edges[e];
            nalgebra::Vector3::new(
                b[4 * e + 1] + delta[3 * va] - delta[3 * vb],
                b[4 * e + 2] + delta[3 * va + 1] - delta[3 * vb + 1],
                b[4 * e + 3] + delta[3 * va + 2] - delta[3 * vb + 2],
            )
        };
        let mut active: Vec<bool> = (0..m)
            .map(|e| Self::is_active(&s[4 * e..4 * e + 4], &z[4 * e..4 * e + 4]))
            .collect();
        let mut start: (Vec<f64>, Vec<f64>) = (x.to_vec(), (0..m).map(|e| z[4 * e]).collect());
        let mut total = 0;
        // A primal active-set loop around Newton: the interior-point solution's active
        // set is nearly always right; an edge that needs a negative multiplier is
        // released, one that ends up over its bound is added. Each round starts from the
        // previous round's Newton solution, which differs only near the changed edges.
        // The rounds share one system over the candidate edges `20 z⁰ > γ` — ten times
        // below the activity threshold — so that a round that adds an edge rarely needs a
        // new symbolic analysis (on the paper-size sheet every added edge was a candidate
        // when the polish started from relative gaps of 1e-3 and 1e-4).
        let candidates: Vec<bool> = (0..m)
            .map(|e| Self::is_loaded_above(&s[4 * e..4 * e + 4], &z[4 * e..4 * e + 4], 0.1))
            .collect();
        let mut system = self.system_over(&candidates).ok()?;
        for _ in 0..6 {
            if !covers(&system, &active) {
                let mut keep = active.clone();
                system.ids().iter().for_each(|&e| keep[e] = true);
                system = self.system_over(&keep).ok()?;
            }
            let (delta, lambda, norm, iterations) =
                self.polish_newton(b, &system, &active, &start.0, &start.1, &d_at)?;
            total += iterations;
            if norm > 1e-12 {
                return None;
            }
            let lambda_max = lambda.iter().fold(0.0f64, |a, b| a.max(*b));
            let mut changed = false;
            for e in 0..m {
                if active[e] && lambda[e] < -1e-10 * lambda_max {
                    active[e] = false;
                    changed = true;
                } else if !active[e] && d_at(&delta, e).norm() > b[4 * e] * (1.0 + 1e-12) {
                    active[e] = true;
                    changed = true;
                }
            }
            if changed {
                start = (delta, lambda);
                continue;
            }
            let mut s = vec![0.0; 4 * m];
            let mut z = vec![0.0; 4 * m];
            for e in 0..m {
                let d = d_at(&delta, e);
                s[4 * e] = b[4 * e];
                s[4 * e + 1..4 * e + 4].copy_from_slice(d.as_slice());
                let le = if active[e] { lambda[e].max(0.0) } else { 0.0 };
                let u = d / d.norm().max(f64::MIN_POSITIVE);
                // z_e = λ_e [1; −u_e]: the dual of ‖d_e‖ ≤ l^max on the cone's boundary.
                z[4 * e] = le;
                for c in 0..3 {
                    z[4 * e + 1 + c] = -le * u[c];
                }
            }
            return Some(Polished {
                x: delta,
                s,
                z,
                iterations: total,
                system,
            });
        }
        None
    }

    /// The edge system over the edges with `keep[e]`: the layer's full one when most
    /// edges are kept, else a restricted one (its symbolic analysis costs about as much
    /// as two numeric factorisations of the full pattern and makes each factorisation
    /// several times cheaper).
    fn system_over(&self, keep: &[bool]) -> Result<Arc<EdgeSystem>> {
        let kept = keep.iter().filter(|&&k| k).count();
        if 2 * kept > keep.len() {
            Ok(self.system.clone())
        } else {
            Ok(Arc::new(self.system.restricted(keep)?))
        }
    }

    /// Newton's method on Eq. 2 with the edges in `active` held at their bounds, from the
    /// displacement `x0` and multipliers `lambda0`. Returns `(δ, λ, relative residual,
    /// iterations)`, or `None` if a factorisation failed or the iteration diverged.
    fn polish_newton(
        &self,
        b: &[f64],
        system: &EdgeSystem,
        active: &[bool],
        x0: &[f64],
        lambda0: &[f64],
        d_at: &dyn Fn(&[f64], usize) -> nalgebra::Vector3<f64>,
    ) -> Option<(Vec<f64>, Vec<f64>, f64, usize)> {
        let m = self.num_constraints();
        let n = x0.len();
        let edges = self.rest.edges();
        let w = self.rest.weights();
        // Residual of Eq. 2 (solver units): K δ + Σ λ_e D_eᵀ u_e and l_e − l_e^max on active edges.
        let residual = |delta: &[f64], lambda: &[f64]| {
            let mut r: Vec<f64> = (0..n).map(|i| w[i / 3] * delta[i]).collect();
            let scale = weft_linalg::max_abs(r.iter().copied()).max(f64::MIN_POSITIVE);
            let mut r_len = vec![0.0; m];
            for e in (0..m).filter(|&e| active[e]) {
                let d = d_at(delta, e);
                let l = d.norm();
                let [va, vb] = edges[e];
                for c in 0..3 {
                    r[3 * va + c] += lambda[e] * d[c] / l;
                    r[3 * vb + c] -= lambda[e] * d[c] / l;
                }
                r_len[e] = l - b[4 * e];
            }
            // A non-finite iterate must read as an infinite residual, never as converged.
            let norm = if scale.is_finite() {
                weft_linalg::max_abs(r.iter().copied()) / scale
            } else {
                f64::INFINITY
            };
            let norm_len = weft_linalg::max_abs((0..m).map(|e| r_len[e] / b[4 * e]));
            (r, r_len, norm.max(norm_len))
        };
        let mut delta = x0.to_vec();
        let mut lambda: Vec<f64> = (0..m)
            .map(|e| if active[e] { lambda0[e].max(0.0) } else { 0.0 })
            .collect();
        let (mut r, mut r_len, mut norm) = residual(&delta, &lambda);
        let mut iterations = 0;
        while norm > 1e-14 && iterations < 10 {
            iterations += 1;
            // The Jacobian of Eq. 2: [K + Σ λ_e D_eᵀ (I − u uᵀ)/l D_e, D_eᵀu_e; u_eᵀD_e, 0],
            // one row per edge of `system` (those of inactive edges decouple).
            let blocks: Vec<EdgeBlock> = system
                .ids()
                .iter()
                .map(|&e| {
                    if !active[e] {
                        return EdgeBlock::decoupled();
                    }
                    let d = d_at(&delta, e);
                    let l = d.norm();
                    let u = d / l;
                    let h = (nalgebra::Matrix3::identity() - u * u.transpose()) * (lambda[e] / l);
                    EdgeBlock {
                        primal: h,
                        coupling: Some(u),
                        diagonal: 0.0,
                    }
                })
                .collect();
            let factor = self.factorize_kkt(system, blocks).ok()?;
            let mut step: Vec<f64> = r
                .iter()
                .chain(system.ids().iter().map(|&e| &r_len[e]))
                .map(|v| -v)
                .collect();
            factor.solve_in_place(&mut step);
            let trial: Vec<f64> = delta.iter().zip(&step).map(|(d, s)| d + s).collect();
            let mut trial_lambda = vec![0.0; m];
            for (k, &e) in system.ids().iter().enumerate() {
                if active[e] {
                    trial_lambda[e] = lambda[e] + step[n + k];
                }
            }
            let (tr, tr_len, tnorm) = residual(&trial, &trial_lambda);
            // Newton from an interior-point solution is in its region of quadratic
            // convergence; an occasional first-step increase (the multipliers of nearly
            // inactive edges being dropped) is allowed, divergence is not.
            if !(tnorm.is_finite() && tnorm < 1e3 * norm.max(1e-12)) {
                return None;
            }
            (delta, lambda, r, r_len, norm) = (trial, trial_lambda, tr, tr_len, tnorm);
        }
        Some((delta, lambda, norm, iterations))
    }

    /// The regularised LDLᵀ of the edge KKT matrix `[K + Σ D_eᵀ B_e D_e, D_eᵀ c_e;
    /// c_eᵀ D_e, σ_e]` (rows first, see `crate::kkt`).
    fn factorize_kkt<'a>(&self, system: &'a EdgeSystem, blocks: Vec<EdgeBlock>) -> Result<KktFactor<'a>> {
        system.factorize_kkt(blocks, self.settings.ldlt_delta, self.settings.refinement_steps)
    }

    /// `∂E/∂r̂` from `∂E/∂r*` (`grad_out`) at a forward solution (Geng et al. Eq. 11).
    pub fn backward(&self, solution: &SocpSolution, grad_out: &[f64]) -> Result<Vec<f64>> {
        self.backward_with_report(solution, grad_out).map(|(g, _)| g)
    }

    /// [`backward`](Self::backward) with a report of the linear solve.
    pub fn backward_with_report(
        &self,
        solution: &SocpSolution,
        grad_out: &[f64],
    ) -> Result<(Vec<f64>, BackwardReport)> {
        let start = Instant::now();
        self.rest.check_positions("output gradient", grad_out)?;
        let n = 3 * self.num_vertices();
        let m = self.num_constraints();
        if solution.s.len() != 4 * m || solution.z.len() != 4 * m || solution.positions.len() != n {
            return Err(Error::LengthMismatch {
                what: "forward state",
                expected: 4 * m,
                got: solution.s.len(),
            });
        }
        // Edges carrying force (Appendix A, last paragraph: the others decouple). After
        // the polish they are its active edges, whose system (and symbolic factor) the
        // solution carries.
        let (s_all, z_all) = (&solution.s, &solution.z);
        let loaded: Vec<bool> = (0..m).map(|e| z_all[4 * e] > 0.0 && s_all[4 * e] > 0.0).collect();
        let system = match &solution.active_system {
            Some(system) if covers(system, &loaded) => system.clone(),
            _ => self.system_over(&loaded)?,
        };
        let mut rows = 0;
        let blocks: Vec<EdgeBlock> = system
            .ids()
            .iter()
            .map(|&e| {
                let (s, z) = (&s_all[4 * e..4 * e + 4], &z_all[4 * e..4 * e + 4]);
                let (s0, z0) = (s[0], z[0]);
                if !loaded[e] {
                    return EdgeBlock::decoupled();
                }
                let s1 = nalgebra::Vector3::new(s[1], s[2], s[3]);
                let s1n = s1.norm();
                // γ = (s⁰² − ‖s¹‖²)/s⁰ without cancellation; ≥ 0 inside the cone.
                let gamma = ((s0 - s1n) * (s0 + s1n) / s0).max(0.0);
                let v = s1 / s0;
                let primal = nalgebra::Matrix3::identity() * (z0 / s0);
                if Self::is_active(s, z) {
                    rows += 1;
                    EdgeBlock {
                        primal,
                        coupling: Some(v),
                        diagonal: -gamma / (2.0 * z0),
                    }
                } else {
                    // Exact elimination of the nearly decoupled row (its Schur complement).
                    EdgeBlock {
                        primal: primal + v * v.transpose() * (2.0 * z0 / gamma),
                        ..EdgeBlock::decoupled()
                    }
                }
            })
            .collect();
        let factor = self.factorize_kkt(&system, blocks)?;
        let mut rhs = vec![0.0; n + system.ids().len()];
        rhs[..n].copy_from_slice(grad_out);
        let linear_residual = factor.solve_in_place(&mut rhs);
        let w = self.rest.weights();
        let grad_in: Vec<f64> = (0..n).map(|i| w[i / 3] * rhs[i]).collect();
        check_output("SOCP backward gradient", &grad_in)?;
        let report = BackwardReport {
            time_seconds: start.elapsed().as_secs_f64(),
            linear_residual,
            constraint_rows: rows,
        };
        Ok((grad_in, report))
    }

    /// [`forward`](Self::forward) over many predictions in parallel (rayon over examples).
    pub fn forward_batch<P: AsRef<[f64]> + Sync>(&self, preds: &[P]) -> Vec<Result<(SocpSolution, SocpReport)>> {
        preds.par_iter().map(|p| self.forward(p.as_ref())).collect()
    }

    /// [`backward`](Self::backward) over many examples in parallel.
    pub fn backward_batch<G: AsRef<[f64]> + Sync>(
        &self,
        solutions: &[SocpSolution],
        grads: &[G],
    ) -> Result<Vec<Vec<f64>>> {
        crate::error::backward_batch(solutions, grads, |s, g| self.backward(s, g))
    }
}

/// Whether every edge with `needed[e]` is in `system`.
fn covers(system: &EdgeSystem, needed: &[bool]) -> bool {
    let mut inside = vec![false; needed.len()];
    system.ids().iter().for_each(|&e| inside[e] = true);
    needed.iter().zip(&inside).all(|(&n, &i)| !n || i)
}
