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

mod backward;
mod clarabel_solver;
mod polish;

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

/// The interior-point tolerance a point is taken to when the polish rejects it (see
/// [`SocpReport::handover_tolerance`]): the tightest the reduced IPM reached on every
/// degenerate heavy-stretch case of the tests (1e-11 failed on some, 1e-12 on most).
pub const HANDOVER_TOLERANCE: f64 = 1e-10;

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
    /// Interior-point iterations of whichever [`ConicSolver`] ran, all of them: when a
    /// continuation toward [`HANDOVER_TOLERANCE`] is given up, its iterations count
    /// although the point returned is the one that met the tolerance.
    pub iterations: u32,
    /// Newton iterations of the active-set polish, `None` if it was off or rejected (the
    /// interior-point solution is returned then).
    pub polish_iterations: Option<usize>,
    /// When the polish was rejected at the requested tolerance, the tighter one
    /// ([`HANDOVER_TOLERANCE`]) the interior-point method continued to before the point
    /// was handed over (its iterations are included in `iterations`).
    pub handover_tolerance: Option<f64>,
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
    /// What [`InextensibilityLayer::forward_from`] needs of this solution — positions and
    /// cone variables — without the backward pass's factorised active-edge system, which
    /// is megabytes on a paper-size mesh (a store of one start per training example must
    /// not keep it).
    pub fn warm_start(&self) -> SocpSolution {
        SocpSolution {
            positions: self.positions.clone(),
            s: self.s.clone(),
            z: self.z.clone(),
            active_system: None,
        }
    }

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

    /// Solves the SOCP for `b` with the reduced-system interior-point method. With the
    /// polish on, its first iterate within `early_polish_gap` and its converged iterate
    /// are polished, and if the polish certifies the optimum that ends the solve. If the
    /// polish rejects the converged point, the iteration continues to
    /// [`HANDOVER_TOLERANCE`] (see [`forward`](Self::forward)) and that point is polished
    /// once more. Returns the solution, the polished point if any, the seconds in the
    /// polish (apart from the interior-point time) and whether the point was handed over
    /// at [`HANDOVER_TOLERANCE`].
    fn solve_reduced_ipm(&self, b: &[f64]) -> Result<(ConicSolution, Option<Polished>, f64, bool)> {
        let polish = self.settings.polish;
        let settings = IpmSettings {
            tolerance: self.settings.tolerance,
            max_iterations: self.settings.max_iterations,
            iterative_refinement: self.settings.iterative_refinement,
            verbose: self.settings.verbose,
            early_finish_gap: if polish { self.settings.early_polish_gap } else { 0.0 },
            fallback_tolerance: if polish { HANDOVER_TOLERANCE } else { 0.0 },
        };
        let mut polish_seconds = 0.0;
        let (sol, polished) = ReducedIpm::new(&self.system).solve(b, &settings, |x, s, z| {
            if !polish {
                return None;
            }
            let start = Instant::now();
            let polished = self.polish(b, x, s, z);
            polish_seconds += start.elapsed().as_secs_f64();
            polished
        })?;
        let handed_over = polished.is_none() && sol.tolerance < self.settings.tolerance;
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
        Ok((conic, polished, polish_seconds, handed_over))
    }

    /// The conic right-hand side `b` of a prediction (module docs).
    fn rhs(&self, pred: &[f64]) -> Vec<f64> {
        let m = self.num_constraints();
        let ell = self.length_scale;
        let mut b = vec![0.0; 4 * m];
        for (e, &[va, vb]) in self.rest.edges().iter().enumerate() {
            let d = edge_vector(pred, va, vb) / ell;
            b[4 * e] = self.max_lengths[e] / ell;
            b[4 * e + 1..4 * e + 4].copy_from_slice(d.as_slice());
        }
        b
    }

    /// [`forward`](Self::forward) warm-started from `previous`, the solution of a nearby
    /// prediction (in training, the same example one step earlier): the polish (Newton on
    /// the active-set conditions) starts from its positions and its active set, and
    /// when it certifies the result the interior-point solve is skipped. Otherwise — the
    /// active set changed too much, or the polish is off — this is the cold
    /// [`forward`](Self::forward). Either way the answer is the projection of `pred`.
    pub fn forward_from(&self, pred: &[f64], previous: Option<&SocpSolution>) -> Result<(SocpSolution, SocpReport)> {
        let Some(prev) = previous.filter(|_| self.settings.polish) else {
            return self.forward(pred);
        };
        let start = Instant::now();
        self.rest.check_positions("prediction", pred)?;
        self.rest.check_positions("previous solution", &prev.positions)?;
        let m = self.num_constraints();
        if prev.s.len() != 4 * m || prev.z.len() != 4 * m {
            return Err(Error::LengthMismatch {
                what: "previous solution's cone variables",
                expected: 4 * m,
                got: prev.s.len().min(prev.z.len()),
            });
        }
        let b = self.rhs(pred);
        let ell = self.length_scale;
        let x0: Vec<f64> = prev.positions.iter().zip(pred).map(|(r, p)| (r - p) / ell).collect();
        let polish_start = Instant::now();
        match self.polish(&b, &x0, &prev.s, &prev.z) {
            Some(polished) => {
                let conic = ConicSolution {
                    x: Vec::new(),
                    s: Vec::new(),
                    z: Vec::new(),
                    status: "warm-start".into(),
                    iterations: 0,
                    seconds: 0.0,
                    primal_residual: 0.0,
                    dual_residual: 0.0,
                };
                let polish_seconds = polish_start.elapsed().as_secs_f64();
                self.finish(pred, start, conic, Some(polished), polish_seconds, None)
            }
            None => self.forward(pred),
        }
    }

    /// Projects the flat prediction `pred` (`3 V` coordinates, metres) onto the
    /// edge-length bounds (Geng et al. Eq. 1).
    pub fn forward(&self, pred: &[f64]) -> Result<(SocpSolution, SocpReport)> {
        let start = Instant::now();
        self.rest.check_positions("prediction", pred)?;
        let b = self.rhs(pred);
        // The reduced IPM polishes inside its iteration and continues to
        // HANDOVER_TOLERANCE when the polish is rejected: on degenerate problems (more
        // edges at their bound than a nearly flat sheet has in-plane freedoms, so the
        // multipliers are not unique and no active-set Newton step is defined) the
        // interior-point point itself is the answer, and at the default tolerance its
        // primal error is about the square root of the tolerance, far above its KKT
        // residual. A failure on the way keeps the point that met the tolerance.
        let (conic, polished, polish_seconds, handed_over) = match self.settings.solver {
            ConicSolver::ReducedIpm => self.solve_reduced_ipm(&b)?,
            ConicSolver::Clarabel => {
                let conic = self.solve_clarabel(&b)?;
                let start = Instant::now();
                let polished = self
                    .settings
                    .polish
                    .then(|| self.polish(&b, &conic.x, &conic.s, &conic.z))
                    .flatten();
                (conic, polished, start.elapsed().as_secs_f64(), false)
            }
        };
        check_output("conic solution", &conic.x)?;
        check_output("conic slacks", &conic.s)?;
        check_output("conic duals", &conic.z)?;
        let handover_tolerance = handed_over.then_some(HANDOVER_TOLERANCE);
        self.finish(pred, start, conic, polished, polish_seconds, handover_tolerance)
    }

    /// The solution and report of a forward pass from its conic and polished points.
    fn finish(
        &self,
        pred: &[f64],
        start: Instant,
        conic: ConicSolution,
        polished: Option<Polished>,
        polish_seconds: f64,
        handover_tolerance: Option<f64>,
    ) -> Result<(SocpSolution, SocpReport)> {
        let m = self.num_constraints();
        let ell = self.length_scale;
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
            handover_tolerance,
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

    /// [`forward_from`](Self::forward_from) over many predictions in parallel, one
    /// previous solution (or none) per prediction; a `previous` of another length makes
    /// every entry an error.
    pub fn forward_batch_from<P: AsRef<[f64]> + Sync>(
        &self,
        preds: &[P],
        previous: &[Option<&SocpSolution>],
    ) -> Vec<Result<(SocpSolution, SocpReport)>> {
        crate::batch::forward_batch_from(preds, previous, |p, prev| self.forward_from(p, prev.copied()))
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
        crate::batch::backward_batch(solutions, grads, |s, g| self.backward(s, g))
    }
}
