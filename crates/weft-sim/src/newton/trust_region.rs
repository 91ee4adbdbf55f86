//! The trust-region globalisation of [`NewtonSolver`]: the exact Hessian's quadratic
//! model minimised inside `‖d‖_M ≤ Δ` by Steihaug–Toint conjugate gradients, with `M` the
//! element-projected Hessian, whose Cholesky factor is the preconditioner and is kept
//! while conjugate gradients converge quickly with it.
//!
//! Why (docs/CLOTH.md, *Ground truth at speed*): a wrinkling sheet sits at a saddle of
//! the step's energy, where the line search's globally shifted matrix `H + τI` has to
//! take `τ` above the most negative curvature (compressed springs, about 10 N/m) and so
//! cuts every soft mode's step (curvature ≈ m/Δt², about 0.1 N/m) to a percent of
//! Newton's, while each indefinite iteration pays several factorisations to find `τ`. The
//! trust region takes the negative-curvature direction to its boundary and the rest of
//! the step at full length, and the factor is of a matrix that is positive definite by
//! construction, so no shift search is needed and one factor serves many iterations.

use std::sync::Arc;

use weft_linalg::{CholeskyFactor, SymmetricMatrix, SymmetricPattern, dot};

use super::{NewtonReport, NewtonSettings, NewtonSolver, Progress, shifted_factor};
use crate::energy::{Energy, total_gradient};
use crate::error::{Error, Result};

/// Conjugate-gradient iterations above which the kept preconditioner is refactorised
/// at the next iteration: the projected Hessian has drifted from the one factorised.
const REFRESH_AFTER_CG: usize = 12;
/// Conjugate-gradient iterations per trust-region subproblem at most.
const MAX_CG: usize = 250;
/// Steps whose energy change is at least this fraction of the model's are accepted.
const ACCEPT_RATIO: f64 = 1e-4;

/// The preconditioner `M` of the trust region: the element-projected Hessian and its
/// Cholesky factor, kept across iterations and calls while it serves.
#[derive(Debug)]
pub(super) struct Preconditioner {
    matrix: SymmetricMatrix,
    factor: Option<CholeskyFactor>,
    /// The diagonal shift its factor needed (0 unless the projected Hessian is singular,
    /// e.g. free rigid modes without inertia).
    shift: f64,
    /// Conjugate-gradient iterations of the last subproblem solved with it.
    last_cg: usize,
}

impl Preconditioner {
    pub(super) fn new(pattern: Arc<SymmetricPattern>) -> Self {
        Self {
            matrix: SymmetricMatrix::zeros(pattern),
            factor: None,
            shift: 0.0,
            last_cg: 0,
        }
    }

    /// Drops the kept factor (the fixed DOFs changed).
    pub(super) fn invalidate(&mut self) {
        self.factor = None;
    }
}

/// `M⁻¹ r` on free DOFs (fixed ones stay 0).
fn precondition(factor: &CholeskyFactor, fixed: &[bool], r: &[f64], z: &mut [f64]) {
    z.copy_from_slice(r);
    factor.solve_in_place(z);
    z.iter_mut().zip(fixed).filter(|(_, f)| **f).for_each(|(v, _)| *v = 0.0);
}

/// What the trust-region subproblem returned.
struct Subproblem {
    /// `‖d‖_M`.
    norm: f64,
    /// Whether `d` ends on the boundary (negative curvature or the radius reached).
    boundary: bool,
    iterations: usize,
}

impl NewtonSolver {
    /// Steihaug–Toint preconditioned CG on `min gᵀd + ½ dᵀHd, ‖d‖_M ≤ radius` (`H` is
    /// `self.hessian`, `g` the free part of `grad`) into `self.dir`, stopping once the
    /// model's residual `‖g + Hd‖∞` is below `stop`. The `M`-norms of the iterates come
    /// from CG's own recurrences (Conn, Gould & Toint, Eqs. 7.5.5–7.5.7), so `M` itself is
    /// never applied.
    fn steihaug(&mut self, factor: &CholeskyFactor, grad: &[f64], radius: f64, stop: f64) -> Subproblem {
        let n = grad.len();
        let fixed = &self.fixed;
        // r = −g − H d (the model's negative gradient), z = M⁻¹ r, p the search direction.
        let mut r: Vec<f64> = grad.iter().zip(fixed).map(|(g, f)| if *f { 0.0 } else { -g }).collect();
        let mut z = vec![0.0; n];
        precondition(factor, fixed, &r, &mut z);
        let mut p = z.clone();
        let mut hp = vec![0.0; n];
        let d = &mut self.dir;
        d.iter_mut().for_each(|v| *v = 0.0);
        let mut rz = dot(&r, &z);
        let (mut dmd, mut dmp, mut pmp): (f64, f64, f64) = (0.0, 0.0, rz);
        let to_boundary = |dmd: f64, dmp: f64, pmp: f64| {
            // The τ ≥ 0 with ‖d + τp‖²_M = Δ².
            (-dmp + (dmp * dmp + pmp * (radius * radius - dmd)).max(0.0).sqrt()) / pmp
        };
        for k in 0..MAX_CG {
            if !(rz > 0.0) {
                // r = 0 (or round-off): d is the model's minimiser.
                return Subproblem {
                    norm: dmd.sqrt(),
                    boundary: false,
                    iterations: k,
                };
            }
            self.hessian.mul_vec(&p, &mut hp);
            let curvature = dot(&p, &hp);
            let alpha = rz / curvature;
            let next = dmd + 2.0 * alpha * dmp + alpha * alpha * pmp;
            // Non-positive curvature, or the CG step would leave the region: go to the
            // boundary along p.
            if curvature <= 0.0 || next >= radius * radius {
                let tau = to_boundary(dmd, dmp, pmp);
                d.iter_mut().zip(&p).for_each(|(v, pi)| *v += tau * pi);
                return Subproblem {
                    norm: radius,
                    boundary: true,
                    iterations: k + 1,
                };
            }
            d.iter_mut().zip(&p).for_each(|(v, pi)| *v += alpha * pi);
            r.iter_mut().zip(&hp).for_each(|(v, h)| *v -= alpha * h);
            dmd = next;
            if weft_linalg::max_abs(r.iter().copied()) <= stop {
                return Subproblem {
                    norm: dmd.sqrt(),
                    boundary: false,
                    iterations: k + 1,
                };
            }
            precondition(factor, fixed, &r, &mut z);
            let rz_next = dot(&r, &z);
            let beta = rz_next / rz;
            dmp = beta * (dmp + alpha * pmp);
            pmp = rz_next + beta * beta * pmp;
            p.iter_mut().zip(&z).for_each(|(v, zi)| *v = zi + beta * *v);
            rz = rz_next;
        }
        Subproblem {
            norm: dmd.sqrt(),
            boundary: false,
            iterations: MAX_CG,
        }
    }

    /// Refactorises the preconditioner at `x` if it has no factor or the last subproblem
    /// needed many CG iterations with it.
    fn refresh_preconditioner(&mut self, terms: &[&dyn Energy], x: &[f64], report: &mut NewtonReport) -> Result<()> {
        let pc = &mut self.preconditioner;
        if pc.factor.is_some() && pc.last_cg <= REFRESH_AFTER_CG {
            return Ok(());
        }
        pc.matrix.set_zero();
        for t in terms {
            t.add_hessian(x, true, &mut pc.matrix);
        }
        pc.matrix.constrain_dofs(&self.fixed);
        report.factorizations += 1;
        let factor = match self.cholesky.factorize(&pc.matrix) {
            Ok(f) => {
                pc.shift = 0.0;
                f
            }
            Err(weft_linalg::Error::NotPositiveDefinite) => {
                let (f, attempts, shift) = shifted_factor(&self.cholesky, &pc.matrix, pc.shift)?;
                report.regularizations += attempts;
                report.factorizations += attempts;
                pc.shift = shift;
                f
            }
            Err(e) => return Err(e.into()),
        };
        pc.factor = Some(factor);
        pc.last_cg = 0;
        Ok(())
    }

    /// Newton iterations with the trust region (see [`super::Globalization`]).
    pub(super) fn trust_region_steps(
        &mut self,
        terms: &[&dyn Energy],
        x: &mut [f64],
        settings: &NewtonSettings,
        progress: &mut Progress,
    ) -> Result<()> {
        let initial_residual = progress.residual;
        let mut radius = f64::NAN;
        let mut assembled = false;
        let mut scratch = vec![0.0; x.len()];
        while progress.iterate(settings)? {
            if !assembled {
                self.hessian.set_zero();
                for t in terms {
                    t.add_hessian(x, false, &mut self.hessian);
                }
                self.hessian.constrain_dofs(&self.fixed);
                let values = self.hessian.values();
                if let Some((_, dof, _)) = self.hessian.pattern().entries().find(|e| !values[e.0].is_finite()) {
                    return Err(Error::NonFinite { what: "Hessian", dof });
                }
                progress.floor = self.residual_floor(x);
                progress.report.residual_floor = progress.floor;
                self.refresh_preconditioner(terms, x, &mut progress.report)?;
                assembled = true;
            }
            let factor = self.preconditioner.factor.take().expect("refreshed above");
            let grad = &progress.grad;
            if radius.is_nan() {
                // The first radius: the preconditioned gradient step's length, the
                // Newton step's if H were M.
                let r: Vec<f64> = grad
                    .iter()
                    .zip(&self.fixed)
                    .map(|(g, f)| if *f { 0.0 } else { -g })
                    .collect();
                precondition(&factor, &self.fixed, &r, &mut scratch);
                radius = dot(&r, &scratch).max(0.0).sqrt();
            }
            // Inexact Newton: the model's residual cut by η = min(½, √(r/r₀)) (a
            // superlinear forcing sequence), and well below the tolerance at the end.
            let residual = progress.residual;
            let eta = (residual / initial_residual.max(f64::MIN_POSITIVE)).sqrt().min(0.5);
            let stop = (eta * residual).max(0.1 * progress.tolerance(settings));
            let sub = self.steihaug(&factor, grad, radius, stop);
            self.preconditioner.factor = Some(factor);
            self.preconditioner.last_cg = sub.iterations;
            progress.report.cg_iterations += sub.iterations;
            // The model's decrease −(gᵀd + ½ dᵀHd) against the energy's.
            let hd = &mut scratch;
            self.hessian.mul_vec(&self.dir, hd);
            let predicted = -(0..x.len())
                .filter(|&i| !self.fixed[i])
                .map(|i| self.dir[i] * (grad[i] + 0.5 * hd[i]))
                .sum::<f64>();
            for i in 0..x.len() {
                self.trial[i] = x[i] + self.dir[i];
            }
            let (change, roundoff) = energy_change(terms, x, &self.trial);
            let measurable = predicted > 64.0 * f64::EPSILON * roundoff;
            let accepted = if measurable {
                change.is_finite() && -change >= ACCEPT_RATIO * predicted
            } else {
                // Below the energy's round-off the ratio carries no information:
                // judge the step by the residual force, as the line search does.
                let trial_grad = &mut scratch;
                total_gradient(terms, &self.trial, trial_grad);
                let r = self.free_residual(trial_grad);
                r.is_finite() && r < residual
            };
            if !accepted {
                progress.report.rejected_steps += 1;
                radius = 0.25 * sub.norm;
                let xmax = weft_linalg::max_abs(x.iter().copied());
                let moved = weft_linalg::max_abs(self.dir.iter().copied());
                if moved <= 4.0 * f64::EPSILON * xmax || !(radius > 0.0) {
                    return Err(progress.not_converged(progress.tolerance(settings)));
                }
                continue;
            }
            let ratio = if measurable { -change / predicted } else { 1.0 };
            if ratio < 0.25 {
                radius = 0.25 * sub.norm;
            } else if ratio > 0.75 && sub.boundary {
                radius *= 2.0;
            }
            progress.energy += change;
            assembled = false;
            if self.take_step(terms, x, settings, progress)? {
                break;
            }
        }
        Ok(())
    }
}

/// The energy change from `x` to `trial`, summed term by term (affine terms exactly, see
/// [`Energy::value_change`]), and the energy's round-off scale (the sum of the non-affine
/// terms' magnitudes at `x`).
fn energy_change(terms: &[&dyn Energy], x: &[f64], trial: &[f64]) -> (f64, f64) {
    let mut change = 0.0;
    let mut scale = 0.0;
    for t in terms {
        if t.is_affine() {
            change += t.value_change(x, trial);
        } else {
            let at_x = t.value(x);
            scale += at_x.abs();
            change += t.value(trial) - at_x;
        }
    }
    (change, scale)
}
