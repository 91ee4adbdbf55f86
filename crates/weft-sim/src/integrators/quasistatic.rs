//! Quasistatic equilibrium with load stepping: `min_x E_int(x) − s f·x` for a load
//! factor `s` ramped from 0 to 1 in increments, each solve started from the previous
//! equilibrium (the standard incremental method of nonlinear FEM, e.g. Bathe, *Finite
//! Element Procedures*, §8.4). An increment whose Newton solve fails is halved and
//! retried, so a load the full step cannot reach is still approached along the path.

use std::time::Instant;

use crate::energies::ConstantForce;
use crate::energy::Energy;
use crate::error::{Error, Result};
use crate::newton::{NewtonReport, NewtonSettings, NewtonSolver};

/// What a load-stepped solve did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct QuasistaticReport {
    /// The load factors at which an equilibrium was reached (the last is 1).
    pub load_factors: Vec<f64>,
    /// One Newton report per converged increment.
    pub newton: Vec<NewtonReport>,
    /// Increments that failed and were halved.
    pub subdivisions: usize,
    /// Wall time (s).
    pub seconds: f64,
}

/// Load-stepped quasistatic equilibrium over a fixed set of internal terms.
#[derive(Debug)]
pub struct Quasistatic {
    solver: NewtonSolver,
    /// Newton settings; the tolerance is replaced per solve by
    /// `relative_tolerance · max|f|` when the load is non-zero.
    pub settings: NewtonSettings,
    /// Residual tolerance relative to the largest load component.
    pub relative_tolerance: f64,
    /// How many times one increment may be halved before giving up.
    pub max_subdivisions: usize,
}

impl Quasistatic {
    /// Prepares the solver for `internal` terms over `num_dofs` DOFs with `fixed` DOFs
    /// held at the values they have in the `x` given to [`Quasistatic::solve`].
    pub fn new(num_dofs: usize, internal: &[&dyn Energy], fixed: Vec<bool>) -> Result<Self> {
        Ok(Self {
            solver: NewtonSolver::new(num_dofs, internal, fixed)?,
            settings: NewtonSettings::default(),
            relative_tolerance: 1e-6,
            max_subdivisions: 8,
        })
    }

    pub fn fixed(&self) -> &[bool] {
        self.solver.fixed()
    }

    /// Solves `∇E_int(x) = f` for the external forces `load` (N, flat) in `load_steps`
    /// equal increments, updating `x` (m) in place. On failure `x` holds the last
    /// converged equilibrium and the error says why.
    pub fn solve(
        &mut self,
        internal: &[&dyn Energy],
        load: &[f64],
        x: &mut [f64],
        load_steps: usize,
    ) -> Result<QuasistaticReport> {
        self.solve_from(internal, None, load, x, load_steps)
    }

    /// As [`Quasistatic::solve`], continuing from an equilibrium `x` under `from` (N,
    /// flat): the increments go from `from` to `load`, not from zero, so a sequence of
    /// growing loads costs one ramp in all, not one per load. `None` is the unloaded body.
    pub fn solve_from(
        &mut self,
        internal: &[&dyn Energy],
        from: Option<&[f64]>,
        load: &[f64],
        x: &mut [f64],
        load_steps: usize,
    ) -> Result<QuasistaticReport> {
        let start = Instant::now();
        if let Some(f) = from {
            if f.len() != load.len() {
                return Err(Error::LengthMismatch {
                    what: "starting load",
                    expected: load.len(),
                    got: f.len(),
                });
            }
        }
        let at = |t: f64, k: usize| match from {
            Some(f) => f[k] + t * (load[k] - f[k]),
            None => t * load[k],
        };
        if load_steps == 0 {
            return Err(Error::InvalidParameter {
                name: "load steps",
                value: 0.0,
                reason: "must be at least 1",
            });
        }
        if load.len() != x.len() {
            return Err(Error::LengthMismatch {
                what: "load",
                expected: x.len(),
                got: load.len(),
            });
        }
        let max_load = load.iter().fold(0.0f64, |m, f| m.max(f.abs()));
        let mut settings = self.settings;
        if max_load > 0.0 {
            settings.tolerance = self.relative_tolerance * max_load;
        }
        let mut report = QuasistaticReport {
            load_factors: Vec::new(),
            newton: Vec::new(),
            subdivisions: 0,
            seconds: 0.0,
        };
        let mut reached = 0.0;
        let mut increment = 1.0 / load_steps as f64;
        let mut halvings = 0;
        let mut last_good = x.to_vec();
        while reached < 1.0 {
            let target = (reached + increment).min(1.0);
            let force = ConstantForce::new("load", (0..load.len()).map(|k| at(target, k)).collect())?;
            let mut all: Vec<&dyn Energy> = internal.to_vec();
            all.push(&force);
            match self.solver.minimize(&all, x, &settings) {
                Ok(newton) => {
                    reached = target;
                    report.load_factors.push(target);
                    report.newton.push(newton);
                    last_good.copy_from_slice(x);
                    halvings = 0;
                    // Grow back towards the nominal increment after a success.
                    increment = (2.0 * increment).min(1.0 / load_steps as f64);
                }
                Err(e @ (Error::NotConverged { .. } | Error::NonFinite { .. } | Error::Linalg(_))) => {
                    x.copy_from_slice(&last_good);
                    if halvings >= self.max_subdivisions {
                        return Err(e);
                    }
                    halvings += 1;
                    report.subdivisions += 1;
                    increment *= 0.5;
                }
                Err(e) => {
                    x.copy_from_slice(&last_good);
                    return Err(e);
                }
            }
        }
        report.seconds = start.elapsed().as_secs_f64();
        Ok(report)
    }
}
