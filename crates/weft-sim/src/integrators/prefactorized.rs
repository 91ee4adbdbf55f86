//! Linear elasticity with a constant, pre-factorised system matrix — the NNWarp runtime
//! (Luo et al., NNWarp §6 and Table 1): factorise once, then one sparse solve per step.
//!
//! The stiffness `K` is the Hessian of the elastic terms at the rest state. Every
//! material of [`crate::energies::TetElasticity`] has the same Hessian there (they all
//! agree with linear elasticity for infinitesimal strain), so `K` is the linear-elastic
//! stiffness whichever material the terms use.
//!
//! In displacements `u = x − x̄` the solves are
//!
//! ```text
//! static:   K u = f
//! dynamic:  (M/Δt² + C/Δt + K) u_{n+1} = f + M (2u_n − u_{n−1})/Δt² + C u_n/Δt,
//!           C = α M + β K   (backward Euler with Rayleigh damping)
//! ```
//!
//! with anchors (Dirichlet DOFs) eliminated symmetrically: their rows and columns are
//! removed from the factorised matrix and their prescribed values moved to the
//! right-hand side.

use std::sync::Arc;
use std::time::Instant;

use weft_linalg::{CholeskyFactor, CholeskySolver, SymmetricMatrix, SymmetricPattern};

use crate::energy::Energy;
use crate::error::{Error, Result, check_nonnegative, check_positive};

/// Rayleigh damping `C = α M + β K` (Rayleigh 1877; standard in structural dynamics):
/// `mass` is `α` (1/s), `stiffness` is `β` (s).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RayleighDamping {
    pub mass: f64,
    pub stiffness: f64,
}

impl RayleighDamping {
    pub const NONE: Self = Self {
        mass: 0.0,
        stiffness: 0.0,
    };

    pub(crate) fn validate(&self) -> Result<()> {
        check_nonnegative("Rayleigh mass damping α", self.mass)?;
        check_nonnegative("Rayleigh stiffness damping β", self.stiffness)
    }
}

/// The matrix pattern coupling every vertex pair some term couples (3 × 3 blocks).
pub(crate) fn pattern_of(num_vertices: usize, terms: &[&dyn Energy]) -> Result<Arc<SymmetricPattern>> {
    let pairs = crate::energy::checked_pairs(3 * num_vertices, terms)?;
    Ok(Arc::new(SymmetricPattern::from_vertex_pairs(num_vertices, pairs)))
}

/// The summed Hessian of `terms` at `x` over `pattern` (unconstrained).
pub(crate) fn assemble_hessian(
    pattern: &Arc<SymmetricPattern>,
    terms: &[&dyn Energy],
    x: &[f64],
    project: bool,
) -> Result<SymmetricMatrix> {
    let mut h = SymmetricMatrix::zeros(pattern.clone());
    for t in terms {
        t.add_hessian(x, project, &mut h);
    }
    if let Some(i) = h.values().iter().position(|v| !v.is_finite()) {
        return Err(Error::NonFinite {
            what: "stiffness matrix entry",
            dof: i,
        });
    }
    Ok(h)
}

/// Which linear system [`PrefactorizedLinear`] solves each step.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LinearSolve {
    /// `K u = f`: static equilibrium under the current load.
    Static,
    /// Backward Euler with time step `dt` (s) and Rayleigh damping.
    Dynamic { dt: f64, damping: RayleighDamping },
}

/// Timings of one pre-factorised step.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct LinearStepReport {
    /// Wall time of the whole step: right-hand side, one solve, state update (s).
    pub seconds: f64,
    /// Wall time of the triangular solves alone (s).
    pub solve_seconds: f64,
}

/// Linear FEM with a constant system matrix factorised once.
#[derive(Debug)]
pub struct PrefactorizedLinear {
    rest: Vec<f64>,
    masses: Vec<f64>,
    fixed: Vec<bool>,
    mode: LinearSolve,
    stiffness: SymmetricMatrix,
    /// The unconstrained system matrix (for moving anchors' right-hand-side terms).
    system: SymmetricMatrix,
    factor: CholeskyFactor,
    u: Vec<f64>,
    u_prev: Vec<f64>,
    /// Symbolic analysis (ordering, elimination tree) time (s).
    pub symbolic_seconds: f64,
    /// Numeric factorisation time (s).
    pub numeric_seconds: f64,
    rhs: Vec<f64>,
    scratch: Vec<f64>,
}

impl PrefactorizedLinear {
    /// Assembles `K` from `stiffness_terms` at `rest` (flat, m), builds the system
    /// matrix of `mode`, eliminates the `fixed` DOFs and factorises. `masses` (kg per
    /// vertex) are used by [`LinearSolve::Dynamic`] only. A static solve fails with
    /// `UnderConstrained` if the anchors leave a rigid motion free (checked on the
    /// geometry, not left to the factorisation).
    pub fn new(
        rest: &[f64],
        stiffness_terms: &[&dyn Energy],
        masses: Vec<f64>,
        fixed: Vec<bool>,
        mode: LinearSolve,
    ) -> Result<Self> {
        let n = rest.len();
        if !n.is_multiple_of(3) {
            return Err(Error::LengthMismatch {
                what: "rest positions (3 per vertex)",
                expected: n / 3 * 3,
                got: n,
            });
        }
        if masses.len() != n / 3 {
            return Err(Error::LengthMismatch {
                what: "vertex masses",
                expected: n / 3,
                got: masses.len(),
            });
        }
        if fixed.len() != n {
            return Err(Error::LengthMismatch {
                what: "fixed-DOF mask",
                expected: n,
                got: fixed.len(),
            });
        }
        if let Some(i) = rest.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "rest position",
                dof: i,
            });
        }
        for &m in &masses {
            check_nonnegative("vertex mass", m)?;
        }
        if mode == LinearSolve::Static {
            let free_rigid_modes = crate::anchors::free_rigid_modes(rest, &fixed);
            if free_rigid_modes > 0 {
                return Err(Error::UnderConstrained { free_rigid_modes });
            }
        }
        let pattern = pattern_of(n / 3, stiffness_terms)?;
        let stiffness = assemble_hessian(&pattern, stiffness_terms, rest, false)?;
        let mut system = stiffness.clone();
        if let LinearSolve::Dynamic { dt, damping } = mode {
            check_positive("time step", dt)?;
            damping.validate()?;
            // M/Δt² + (αM + βK)/Δt + K.
            system
                .values_mut()
                .iter_mut()
                .for_each(|v| *v *= 1.0 + damping.stiffness / dt);
            for (i, m) in masses.iter().enumerate() {
                for k in 0..3 {
                    system.add(3 * i + k, 3 * i + k, m / (dt * dt) + damping.mass * m / dt);
                }
            }
        }
        let mut constrained = system.clone();
        constrained.constrain_dofs(&fixed);
        let t0 = Instant::now();
        let solver = CholeskySolver::new(pattern)?;
        let t1 = Instant::now();
        let factor = solver.factorize(&constrained)?;
        let t2 = Instant::now();
        Ok(Self {
            rest: rest.to_vec(),
            masses,
            fixed,
            mode,
            stiffness,
            system,
            factor,
            u: vec![0.0; n],
            u_prev: vec![0.0; n],
            symbolic_seconds: (t1 - t0).as_secs_f64(),
            numeric_seconds: (t2 - t1).as_secs_f64(),
            rhs: vec![0.0; n],
            scratch: vec![0.0; n],
        })
    }

    /// Total factorisation time, symbolic + numeric (s).
    pub fn factorization_seconds(&self) -> f64 {
        self.symbolic_seconds + self.numeric_seconds
    }
    /// The linear-elastic stiffness `K` (N/m), unconstrained.
    pub fn stiffness(&self) -> &SymmetricMatrix {
        &self.stiffness
    }
    pub fn mode(&self) -> LinearSolve {
        self.mode
    }
    pub fn fixed(&self) -> &[bool] {
        &self.fixed
    }
    /// Current displacements `u` (m).
    pub fn displacements(&self) -> &[f64] {
        &self.u
    }
    /// Current positions `x̄ + u` (m).
    pub fn positions(&self) -> Vec<f64> {
        self.rest.iter().zip(&self.u).map(|(x, u)| x + u).collect()
    }
    /// Resets to rest, at rest.
    pub fn reset(&mut self) {
        self.u.iter_mut().for_each(|v| *v = 0.0);
        self.u_prev.iter_mut().for_each(|v| *v = 0.0);
    }

    /// One step under external forces `forces` (N, flat) with anchors `prescribed` as
    /// `(dof, position)` pairs (m; fixed DOFs not listed keep their current position).
    pub fn step(&mut self, forces: &[f64], prescribed: &[(usize, f64)]) -> Result<LinearStepReport> {
        let start = Instant::now();
        let n = self.u.len();
        if forces.len() != n {
            return Err(Error::LengthMismatch {
                what: "external forces",
                expected: n,
                got: forces.len(),
            });
        }
        if let Some(i) = forces.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "external force",
                dof: i,
            });
        }
        crate::anchors::check_prescribed(prescribed, &self.fixed)?;
        // Anchor displacements g: current values, overridden by the prescribed ones.
        let mut g = std::mem::take(&mut self.scratch);
        for i in 0..n {
            g[i] = if self.fixed[i] { self.u[i] } else { 0.0 };
        }
        for &(dof, value) in prescribed {
            g[dof] = value - self.rest[dof];
        }
        self.rhs.copy_from_slice(forces);
        if let LinearSolve::Dynamic { dt, damping } = self.mode {
            // + M(2u_n − u_{n−1})/Δt² + (αM u_n + βK u_n)/Δt.
            for (i, m) in self.masses.iter().enumerate() {
                for k in 0..3 {
                    let d = 3 * i + k;
                    self.rhs[d] +=
                        m * (2.0 * self.u[d] - self.u_prev[d]) / (dt * dt) + damping.mass * m * self.u[d] / dt;
                }
            }
            if damping.stiffness > 0.0 {
                let mut ku = vec![0.0; n];
                self.stiffness.mul_vec(&self.u, &mut ku);
                self.rhs
                    .iter_mut()
                    .zip(&ku)
                    .for_each(|(r, k)| *r += damping.stiffness * k / dt);
            }
        }
        if g.iter().any(|&v| v != 0.0) {
            // Move the anchors' columns to the right-hand side.
            let mut ag = vec![0.0; n];
            self.system.mul_vec(&g, &mut ag);
            self.rhs.iter_mut().zip(&ag).for_each(|(r, a)| *r -= a);
        }
        for i in 0..n {
            if self.fixed[i] {
                self.rhs[i] = g[i];
            }
        }
        let solve_start = Instant::now();
        self.factor.solve_in_place(&mut self.rhs);
        let solve_seconds = solve_start.elapsed().as_secs_f64();
        if let Some(i) = self.rhs.iter().position(|v| !v.is_finite()) {
            self.scratch = g;
            return Err(Error::NonFinite {
                what: "linear solve result",
                dof: i,
            });
        }
        std::mem::swap(&mut self.u_prev, &mut self.u);
        self.u.copy_from_slice(&self.rhs);
        self.scratch = g;
        Ok(LinearStepReport {
            seconds: start.elapsed().as_secs_f64(),
            solve_seconds,
        })
    }
}
