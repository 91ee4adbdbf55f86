//! Optimisation-based implicit Euler (Tan et al. Eq. 4; Martin et al. 2011 "Example-based
//! elastic materials", Liu et al. 2013): each step minimises
//!
//! ```text
//! L_phys(p_{m−2}, p_{m−1}, p, q) = ‖p − 2p_{m−1} + p_{m−2}‖²_M / (2Δt²) + P(p, q)
//! ```
//!
//! over the free DOFs, with the grasped DOFs prescribed to `q`. The minimiser is exactly
//! the backward-Euler update, and its gradient is the residual force whose squared norm
//! is Tan's physical-plausibility metric `M_phys` (Eq. 9).

use std::time::Instant;

use crate::energies::Inertia;
use crate::energy::{Energy, total_gradient};
use crate::error::{Error, Result};
use crate::newton::{NewtonReport, NewtonSettings, NewtonSolver};

/// What one time step did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StepReport {
    pub newton: NewtonReport,
    /// Total potential (everything but inertia) at the end of the step (J).
    pub potential_energy: f64,
    /// Kinetic energy `½ Σ m v²` with `v = (p_m − p_{m−1})/Δt` (J).
    pub kinetic_energy: f64,
    /// Wall time of the whole step, including bookkeeping (s).
    pub seconds: f64,
}

/// Tan et al.'s `M_phys` with its two forces squared apart
/// ([`ImplicitEuler::m_phys_parts`]); N².
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ForceResidual {
    /// `‖∂L_phys/∂p_m‖²`: `M_phys`.
    pub total: f64,
    /// `‖M(p_m − 2p_{m−1} + p_{m−2})/Δt²‖²`.
    pub inertial: f64,
    /// `‖∇P(p_m)‖²`.
    pub potential: f64,
}

/// The implicit Euler integrator over a list of potential terms.
#[derive(Debug)]
pub struct ImplicitEuler {
    inertia: Inertia,
    terms: Vec<Box<dyn Energy>>,
    solver: NewtonSolver,
    fixed: Vec<bool>,
    /// `p_m` after the last step (initially the rest state).
    current: Vec<f64>,
    previous: Vec<f64>,
    pub settings: NewtonSettings,
}

impl ImplicitEuler {
    /// `masses` (kg) per vertex, time step `dt` (s), initial positions `x0` (at rest:
    /// `p_{−1} = p_0`), potential `terms`, and the mask of DOFs that are prescribed
    /// (grasp points / anchors).
    pub fn new(masses: Vec<f64>, dt: f64, x0: Vec<f64>, terms: Vec<Box<dyn Energy>>, fixed: Vec<bool>) -> Result<Self> {
        if x0.len() != 3 * masses.len() {
            return Err(Error::LengthMismatch {
                what: "initial positions",
                expected: 3 * masses.len(),
                got: x0.len(),
            });
        }
        if let Some(i) = x0.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "initial position",
                dof: i,
            });
        }
        let inertia = Inertia::new(masses, dt, &x0)?;
        let solver = {
            let all = crate::energy::with_extra(&terms, &[&inertia]);
            NewtonSolver::new(x0.len(), &all, fixed.clone())?
        };
        // Default tolerance: 1e-5 of the heaviest vertex's weight — scale-aware across
        // mesh resolutions and materials.
        let max_weight = inertia.masses().iter().fold(0.0f64, |m, x| m.max(*x)) * 9.81;
        let settings = NewtonSettings {
            tolerance: 1e-5 * max_weight.max(1e-12),
            ..NewtonSettings::default()
        };
        Ok(Self {
            inertia,
            terms,
            solver,
            fixed,
            previous: x0.clone(),
            current: x0,
            settings,
        })
    }

    pub fn positions(&self) -> &[f64] {
        &self.current
    }
    pub fn previous_positions(&self) -> &[f64] {
        &self.previous
    }
    pub fn dt(&self) -> f64 {
        self.inertia.dt()
    }
    pub fn masses(&self) -> &[f64] {
        self.inertia.masses()
    }
    pub fn fixed(&self) -> &[bool] {
        &self.fixed
    }
    pub fn terms(&self) -> &[Box<dyn Energy>] {
        &self.terms
    }
    pub fn terms_mut(&mut self) -> &mut [Box<dyn Energy>] {
        &mut self.terms
    }

    /// Resets the state to `x` at rest (`p_{m−1} = p_m = x`).
    pub fn set_state(&mut self, x: &[f64], previous: &[f64]) -> Result<()> {
        if x.len() != self.current.len() || previous.len() != self.current.len() {
            return Err(Error::LengthMismatch {
                what: "state",
                expected: self.current.len(),
                got: x.len(),
            });
        }
        self.current.copy_from_slice(x);
        self.previous.copy_from_slice(previous);
        Ok(())
    }

    /// Advances one step with the prescribed DOFs set to `prescribed` (`(dof, value)`,
    /// metres). DOFs not in the fixed mask may not be prescribed. On error the state is
    /// left unchanged, so a caller can retry with a smaller step.
    pub fn step(&mut self, prescribed: &[(usize, f64)]) -> Result<StepReport> {
        let start = Instant::now();
        // Start from the inertial prediction (a better guess than p_{m−1} for fast
        // motion), with the prescribed DOFs moved into place.
        let mut x = self.inertial_start(prescribed)?;
        let settings = self.settings;
        let newton = self.solve_step_from(prescribed, &mut x, &settings)?;
        let potential_energy = self.terms.iter().map(|t| t.value(&x)).sum();
        let dt = self.dt();
        let kinetic_energy = self
            .masses()
            .iter()
            .enumerate()
            .map(|(i, m)| {
                let v2: f64 = (0..3)
                    .map(|k| ((x[3 * i + k] - self.current[3 * i + k]) / dt).powi(2))
                    .sum();
                0.5 * m * v2
            })
            .sum();
        self.previous = std::mem::replace(&mut self.current, x);
        Ok(StepReport {
            newton,
            potential_energy,
            kinetic_energy,
            seconds: start.elapsed().as_secs_f64(),
        })
    }

    /// The solver's own start for the next step: the inertial prediction
    /// `2p_m − p_{m−1}` (`x + Δt v`), with unprescribed fixed DOFs held at `p_m` and the
    /// prescribed ones at their values.
    pub fn inertial_start(&self, prescribed: &[(usize, f64)]) -> Result<Vec<f64>> {
        crate::anchors::check_prescribed(prescribed, &self.fixed)?;
        let mut x: Vec<f64> = self
            .current
            .iter()
            .zip(&self.previous)
            .map(|(c, p)| 2.0 * c - p)
            .collect();
        self.constrain(prescribed, &mut x);
        Ok(x)
    }

    /// Sets the fixed DOFs of `x` to the step's constraints: prescribed ones to their
    /// values, the others held at `p_m`.
    pub fn constrain(&self, prescribed: &[(usize, f64)], x: &mut [f64]) {
        for (i, f) in self.fixed.iter().enumerate() {
            if *f {
                x[i] = self.current[i];
            }
        }
        for &(dof, value) in prescribed {
            x[dof] = value;
        }
    }

    /// Solves the next step's minimisation from the start `x` (updated in place to the
    /// minimiser; its fixed DOFs are first set by [`ImplicitEuler::constrain`]) with
    /// `settings`, without advancing the state: the guarded roll-out (`crate::guard`)
    /// starts Newton from a surrogate's proposal and commits with
    /// [`ImplicitEuler::advance_to`].
    pub fn solve_step_from(
        &mut self,
        prescribed: &[(usize, f64)],
        x: &mut [f64],
        settings: &NewtonSettings,
    ) -> Result<NewtonReport> {
        crate::anchors::check_prescribed(prescribed, &self.fixed)?;
        if x.len() != self.current.len() {
            return Err(Error::LengthMismatch {
                what: "step start",
                expected: self.current.len(),
                got: x.len(),
            });
        }
        self.inertia.set_history(&self.current, &self.previous)?;
        self.constrain(prescribed, x);
        let all = crate::energy::with_extra(&self.terms, &[&self.inertia]);
        self.solver.minimize(&all, x, settings)
    }

    /// Advances the state to `x` as the next frame (`p_{m−1} ← p_m`, `p_m ← x`) without
    /// solving: a frame the caller has already checked.
    pub fn advance_to(&mut self, x: &[f64]) -> Result<()> {
        if x.len() != self.current.len() {
            return Err(Error::LengthMismatch {
                what: "next frame",
                expected: self.current.len(),
                got: x.len(),
            });
        }
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "next frame",
                dof: i,
            });
        }
        self.previous.copy_from_slice(&self.current);
        self.current.copy_from_slice(x);
        Ok(())
    }

    /// `L_phys(p_{m−2}, p_{m−1}, p, q)` (Tan et al. Eq. 4) for any frame `p` (with the
    /// grasped DOFs of `p` taken as `q`), in joules.
    pub fn l_phys(&self, prev2: &[f64], prev1: &[f64], p: &[f64]) -> Result<f64> {
        let inertia = self.history_inertia(prev2, prev1, p)?;
        Ok(inertia.value(p) + self.terms.iter().map(|t| t.value(p)).sum::<f64>())
    }

    /// `∂L_phys/∂p_m` at `p` (N), written into `grad` (full length; grasped DOFs included).
    pub fn l_phys_gradient(&self, prev2: &[f64], prev1: &[f64], p: &[f64], grad: &mut [f64]) -> Result<()> {
        let inertia = self.history_inertia(prev2, prev1, p)?;
        if grad.len() != p.len() {
            return Err(Error::LengthMismatch {
                what: "gradient buffer",
                expected: p.len(),
                got: grad.len(),
            });
        }
        let all = crate::energy::with_extra(&self.terms, &[&inertia]);
        total_gradient(&all, p, grad);
        Ok(())
    }

    /// The diagonal of `∂²L_phys/∂p_m²` at `p` (N/m), per-element blocks projected to
    /// positive semi-definite: `M/Δt²` plus the potential's stiffness. Its mean over the
    /// free DOFs is the curvature a loss built on `L_phys` must be normalised by to weigh
    /// the same on a soft sheet and a stiff FEM ball (`docs/EMBEDDING.md`).
    pub fn l_phys_hessian_diagonal(&self, prev2: &[f64], prev1: &[f64], p: &[f64]) -> Result<Vec<f64>> {
        let inertia = self.history_inertia(prev2, prev1, p)?;
        let all = crate::energy::with_extra(&self.terms, &[&inertia]);
        crate::energy::total_hessian_diagonal(p.len(), &all, p, true)
    }

    /// Tan et al.'s `M_phys = ‖∂L_phys/∂p_m‖²` over free DOFs (grasped DOFs carry the
    /// reaction force and are excluded, weft's convention, `docs/CLOTH.md`); N².
    pub fn m_phys(&self, prev2: &[f64], prev1: &[f64], p: &[f64]) -> Result<f64> {
        let mut g = vec![0.0; p.len()];
        self.l_phys_gradient(prev2, prev1, p, &mut g)?;
        Ok(g.iter()
            .zip(&self.fixed)
            .filter(|(_, f)| !**f)
            .map(|(g, _)| g * g)
            .sum())
    }

    /// [`ImplicitEuler::m_phys`] and the two forces it sums, each squared on its own over
    /// the free DOFs: the inertial force `M(p_m − 2p_{m−1} + p_{m−2})/Δt²` and the
    /// potential's `∇P(p_m)` (elastic, bending, gravity, contact). On a simulated frame the
    /// two cancel and the total is the solver's tolerance; on reconstructed frames the
    /// split says which one a residual comes from. The inertial force of three frames with
    /// independent position errors of size ε is of order `4 m ε / Δt²`, so it can dominate
    /// whatever the elastic forces do (docs/EMBEDDING.md). N².
    pub fn m_phys_parts(&self, prev2: &[f64], prev1: &[f64], p: &[f64]) -> Result<ForceResidual> {
        let inertia = self.history_inertia(prev2, prev1, p)?;
        let (mut inertial, mut potential) = (vec![0.0; p.len()], vec![0.0; p.len()]);
        inertia.add_gradient(p, &mut inertial);
        let terms: Vec<&dyn Energy> = self.terms.iter().map(|t| t.as_ref()).collect();
        total_gradient(&terms, p, &mut potential);
        let free_sum =
            |f: &dyn Fn(usize) -> f64| -> f64 { (0..p.len()).filter(|&i| !self.fixed[i]).map(|i| f(i).powi(2)).sum() };
        Ok(ForceResidual {
            total: free_sum(&|i| inertial[i] + potential[i]),
            inertial: free_sum(&|i| inertial[i]),
            potential: free_sum(&|i| potential[i]),
        })
    }

    /// The forces `∂L_phys/∂p_m` sums, each on its own over every DOF (grasped ones
    /// included; N): the inertial force `M(p_m − 2p_{m−1} + p_{m−2})/Δt²` first, named
    /// `"inertia"`, then each potential term's gradient under the term's name
    /// ([`Energy::name`]). [`ImplicitEuler::m_phys_parts`] squares their sums; this keeps
    /// them apart so a residual can be split by energy term and by region of the mesh
    /// (docs/EMBEDDING.md, "Gradient norms and the M_phys floor").
    pub fn l_phys_forces(&self, prev2: &[f64], prev1: &[f64], p: &[f64]) -> Result<Vec<(&'static str, Vec<f64>)>> {
        let inertia = self.history_inertia(prev2, prev1, p)?;
        let all = crate::energy::with_extra(&self.terms, &[&inertia]);
        // `with_extra` puts the extra terms last; the inertia is reported first.
        let mut out: Vec<(&'static str, Vec<f64>)> = all
            .iter()
            .map(|t| {
                let mut g = vec![0.0; p.len()];
                t.add_gradient(p, &mut g);
                (t.name(), g)
            })
            .collect();
        out.rotate_right(1);
        Ok(out)
    }

    fn history_inertia(&self, prev2: &[f64], prev1: &[f64], p: &[f64]) -> Result<Inertia> {
        let n = self.current.len();
        for (what, v) in [("p_{m-2}", prev2), ("p_{m-1}", prev1), ("p_m", p)] {
            if v.len() != n {
                return Err(Error::LengthMismatch {
                    what,
                    expected: n,
                    got: v.len(),
                });
            }
        }
        let mut inertia = self.inertia.clone();
        inertia.set_history(prev1, prev2)?;
        Ok(inertia)
    }
}
