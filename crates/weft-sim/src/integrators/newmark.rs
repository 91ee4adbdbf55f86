//! Newmark's average-acceleration method (β = ¼, γ = ½; Newmark 1959) with Rayleigh
//! damping, solved as a minimisation by the one [`NewtonSolver`].
//!
//! With `x_{n+1} = x_n + Δt v_n + Δt²/4 (a_n + a_{n+1})` and
//! `v_{n+1} = v_n + Δt/2 (a_n + a_{n+1})`, the equation of motion
//! `M a_{n+1} + C v_{n+1} + ∇E(x_{n+1}) = 0` with a constant `C = αM + βK₀` is the
//! stationarity condition of
//!
//! ```text
//! Φ(x) = 2/Δt² ‖x − y‖²_M + 1/Δt ‖x − x_n‖²_C − (C v_n)·x + E(x),   y = x_n + Δt v_n + Δt²/4 a_n
//! ```
//!
//! (the variational form of Kane et al. 2000 for the trapezoidal rule). `K₀` is the
//! (PSD-projected) Hessian of the potential at the initial state, so the stiffness
//! damping is the linear Rayleigh model. Without damping the method conserves the
//! energy of a linear system exactly and of a nonlinear one to O(Δt²).

use std::sync::Arc;
use std::time::Instant;

use weft_linalg::{SymmetricMatrix, SymmetricPattern};

use crate::energies::ZeroLengthSprings;
use crate::energy::{Energy, total_gradient};
use crate::error::{Error, Result, check_nonnegative, check_positive};
use crate::integrators::prefactorized::{RayleighDamping, assemble_hessian, pattern_of};
use crate::newton::{NewtonReport, NewtonSettings, NewtonSolver};

/// What one Newmark step did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct NewmarkReport {
    pub newton: NewtonReport,
    /// Total potential at the end of the step (J).
    pub potential_energy: f64,
    /// `½ vᵀ M v` at the end of the step (J).
    pub kinetic_energy: f64,
    /// Wall time of the whole step (s).
    pub seconds: f64,
}

/// `E = ½ s (x − c)ᵀ A (x − c)` for a constant symmetric matrix `A` (the stiffness part
/// of Rayleigh damping).
#[derive(Debug, Clone)]
struct QuadraticForm {
    matrix: SymmetricMatrix,
    pairs: Vec<(usize, usize)>,
    scale: f64,
    center: Vec<f64>,
}

impl QuadraticForm {
    fn apply(&self, x: &[f64]) -> Vec<f64> {
        let d: Vec<f64> = x.iter().zip(&self.center).map(|(x, c)| x - c).collect();
        let mut ad = vec![0.0; d.len()];
        self.matrix.mul_vec(&d, &mut ad);
        ad
    }
}

impl Energy for QuadraticForm {
    fn name(&self) -> &'static str {
        "Rayleigh stiffness damping"
    }
    fn hessian_pairs(&self, pairs: &mut Vec<(usize, usize)>) {
        pairs.extend_from_slice(&self.pairs);
    }
    fn value(&self, x: &[f64]) -> f64 {
        let ad = self.apply(x);
        0.5 * self.scale
            * ad.iter()
                .zip(x.iter().zip(&self.center))
                .map(|(a, (x, c))| a * (x - c))
                .sum::<f64>()
    }
    fn add_gradient(&self, x: &[f64], grad: &mut [f64]) {
        let ad = self.apply(x);
        grad.iter_mut().zip(&ad).for_each(|(g, a)| *g += self.scale * a);
    }
    fn add_hessian(&self, _x: &[f64], _project: bool, hessian: &mut SymmetricMatrix) {
        if Arc::ptr_eq(hessian.pattern(), self.matrix.pattern())
            || hessian.pattern().nnz() == self.matrix.pattern().nnz()
        {
            // The target pattern contains this one (our pairs are in it) and has the same
            // size, so the layouts coincide.
            let s = self.scale;
            hessian
                .values_mut()
                .iter_mut()
                .zip(self.matrix.values())
                .for_each(|(h, a)| *h += s * a);
        } else {
            for (slot, r, c) in self.matrix.pattern().entries() {
                hessian.add(r, c, self.scale * self.matrix.values()[slot]);
            }
        }
    }
}

/// The Newmark integrator over a list of potential terms.
#[derive(Debug)]
pub struct Newmark {
    masses: Vec<f64>,
    dt: f64,
    damping: RayleighDamping,
    terms: Vec<Box<dyn Energy>>,
    inertia: ZeroLengthSprings,
    stiffness_damping: Option<QuadraticForm>,
    solver: NewtonSolver,
    fixed: Vec<bool>,
    x: Vec<f64>,
    v: Vec<f64>,
    a: Vec<f64>,
    pub settings: NewtonSettings,
}

impl Newmark {
    /// `masses` (kg per vertex), time step `dt` (s), initial positions `x0` (m) and
    /// velocities `v0` (m/s), potential `terms`, the mask of prescribed DOFs and the
    /// Rayleigh damping. The initial acceleration solves `M a₀ = −∇E(x₀) − C v₀` on free
    /// DOFs (zero on fixed ones).
    pub fn new(
        masses: Vec<f64>,
        dt: f64,
        x0: Vec<f64>,
        v0: Vec<f64>,
        terms: Vec<Box<dyn Energy>>,
        fixed: Vec<bool>,
        damping: RayleighDamping,
    ) -> Result<Self> {
        check_positive("time step", dt)?;
        damping.validate()?;
        let n = 3 * masses.len();
        for (what, len) in [
            ("initial positions", x0.len()),
            ("initial velocities", v0.len()),
            ("fixed-DOF mask", fixed.len()),
        ] {
            if len != n {
                return Err(Error::LengthMismatch {
                    what,
                    expected: n,
                    got: len,
                });
            }
        }
        for &m in &masses {
            check_nonnegative("vertex mass", m)?;
        }
        if let Some(i) = x0.iter().chain(&v0).position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "initial state",
                dof: i % n,
            });
        }
        let refs: Vec<&dyn Energy> = terms.iter().map(|t| t.as_ref()).collect();
        let stiffness_damping = if damping.stiffness > 0.0 {
            let pattern: Arc<SymmetricPattern> = pattern_of(masses.len(), &refs)?;
            let mut pairs = Vec::new();
            refs.iter().for_each(|t| t.hessian_pairs(&mut pairs));
            let matrix = assemble_hessian(&pattern, &refs, &x0, true)?;
            Some(QuadraticForm {
                matrix,
                pairs,
                scale: 0.0,
                center: x0.clone(),
            })
        } else {
            None
        };
        let inertia = ZeroLengthSprings::new("Newmark inertia", vec![0.0; masses.len()], x0.clone())?;
        let solver = {
            let mut all = refs.clone();
            all.push(&inertia);
            if let Some(q) = &stiffness_damping {
                all.push(q);
            }
            NewtonSolver::new(n, &all, fixed.clone())?
        };
        // a₀ = −M⁻¹(∇E(x₀) + C v₀) on free DOFs.
        let mut force = vec![0.0; n];
        total_gradient(&refs, &x0, &mut force);
        if let Some(q) = &stiffness_damping {
            let mut kv = vec![0.0; n];
            q.matrix.mul_vec(&v0, &mut kv);
            force.iter_mut().zip(&kv).for_each(|(f, k)| *f += damping.stiffness * k);
        }
        let a: Vec<f64> = (0..n)
            .map(|d| {
                let m = masses[d / 3];
                if fixed[d] || m == 0.0 {
                    0.0
                } else {
                    -(force[d] + damping.mass * m * v0[d]) / m
                }
            })
            .collect();
        if let Some(i) = a.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "initial acceleration",
                dof: i,
            });
        }
        let max_weight = masses.iter().fold(0.0f64, |m, x| m.max(*x)) * 9.81;
        let settings = NewtonSettings {
            tolerance: 1e-6 * max_weight.max(1e-12),
            ..NewtonSettings::default()
        };
        Ok(Self {
            masses,
            dt,
            damping,
            terms,
            inertia,
            stiffness_damping,
            solver,
            fixed,
            x: x0,
            v: v0,
            a,
            settings,
        })
    }

    pub fn positions(&self) -> &[f64] {
        &self.x
    }
    pub fn velocities(&self) -> &[f64] {
        &self.v
    }
    pub fn accelerations(&self) -> &[f64] {
        &self.a
    }
    pub fn dt(&self) -> f64 {
        self.dt
    }
    pub fn masses(&self) -> &[f64] {
        &self.masses
    }
    pub fn terms(&self) -> &[Box<dyn Energy>] {
        &self.terms
    }

    /// Kinetic energy `½ vᵀ M v` (J).
    pub fn kinetic_energy(&self) -> f64 {
        self.v
            .iter()
            .enumerate()
            .map(|(d, v)| 0.5 * self.masses[d / 3] * v * v)
            .sum()
    }
    /// Total potential of the terms at the current positions (J).
    pub fn potential_energy(&self) -> f64 {
        self.terms.iter().map(|t| t.value(&self.x)).sum()
    }

    /// Advances one step with the prescribed DOFs set to `prescribed` (`(dof, value)`,
    /// m). On error the state is left unchanged.
    pub fn step(&mut self, prescribed: &[(usize, f64)]) -> Result<NewmarkReport> {
        let start = Instant::now();
        let n = self.x.len();
        crate::anchors::check_prescribed(prescribed, &self.fixed)?;
        let (dt, alpha) = (self.dt, self.damping.mass);
        let y: Vec<f64> = (0..n)
            .map(|d| self.x[d] + dt * self.v[d] + 0.25 * dt * dt * self.a[d])
            .collect();
        // Diagonal part ½W(x − t)²: W = 4m/Δt² + 2αm/Δt, t = (4m/Δt² y + 2αm/Δt x_n + αm v_n)/W.
        let mut weights = vec![0.0; self.masses.len()];
        let mut targets = vec![0.0; n];
        for (i, &m) in self.masses.iter().enumerate() {
            let (wi, wd) = (4.0 * m / (dt * dt), 2.0 * alpha * m / dt);
            weights[i] = wi + wd;
            for k in 0..3 {
                let d = 3 * i + k;
                targets[d] = if wi + wd > 0.0 {
                    (wi * y[d] + wd * self.x[d] + alpha * m * self.v[d]) / (wi + wd)
                } else {
                    y[d]
                };
            }
        }
        self.inertia.set_weights(&weights)?;
        self.inertia.set_targets(&targets)?;
        if let Some(q) = &mut self.stiffness_damping {
            q.scale = 2.0 * self.damping.stiffness / dt;
            q.center = (0..n).map(|d| self.x[d] + 0.5 * dt * self.v[d]).collect();
        }
        let mut x = y.clone();
        for d in 0..n {
            if self.fixed[d] {
                x[d] = self.x[d];
            }
        }
        for &(dof, value) in prescribed {
            x[dof] = value;
        }
        let newton = {
            let mut all = crate::energy::with_extra(&self.terms, &[&self.inertia]);
            if let Some(q) = &self.stiffness_damping {
                all.push(q);
            }
            self.solver.minimize(&all, &mut x, &self.settings)?
        };
        for d in 0..n {
            let a_new = 4.0 / (dt * dt) * (x[d] - y[d]);
            self.v[d] = 2.0 / dt * (x[d] - self.x[d]) - self.v[d];
            self.a[d] = a_new;
        }
        self.x = x;
        Ok(NewmarkReport {
            newton,
            potential_energy: self.potential_energy(),
            kinetic_energy: self.kinetic_energy(),
            seconds: start.elapsed().as_secs_f64(),
        })
    }
}
