//! Truncated Newton–Krylov minimisation (Geng et al. §5 solve their quasistatic problem
//! with a preconditioned Newton–Krylov method): each Newton step solves `H d = −g` only
//! approximately, by conjugate gradients preconditioned with the inverses of `H`'s
//! `3 × 3` diagonal blocks, to a relative residual `η = min(½, √(‖g‖∞ / F))` with `F` the
//! problem's force scale (the superlinear forcing of Nocedal & Wright, *Numerical
//! Optimization*, §7.1; it depends on the gradient alone, so a warm start close to the
//! answer is solved tightly from its first step), followed by an Armijo line search. No matrix is
//! factorised, so a step costs a Hessian assembly and tens of sparse products, and a
//! start near the answer (a warm start) costs one or two steps.
//!
//! CG needs a positive definite matrix. Far from the minimum the Hessian is the per-spring
//! PSD projection (Teran et al. 2005), which the zero-length springs make definite; near it
//! (within `10⁴ ×` the tolerance, as the Cholesky path) the true Hessian, for Newton's fast
//! local convergence. CG stops at the first direction of non-positive curvature and the
//! step uses the iterate so far (or the preconditioned gradient, if that was the first
//! direction): a descent direction either way (Nocedal & Wright, *Numerical
//! Optimization*, Alg. 7.1).

use nalgebra::{Matrix3, Vector3};
use weft_linalg::{SymmetricMatrix, dot, pcg};
use weft_sim::Energy;
use weft_sim::energy::{total_gradient, total_value};

/// `H`'s `3 × 3` diagonal blocks, inverted.
struct BlockJacobi {
    inv: Vec<Matrix3<f64>>,
}

impl BlockJacobi {
    fn new(h: &SymmetricMatrix) -> Self {
        let n = h.dim() / 3;
        let inv = (0..n)
            .map(|v| {
                let b = match h.diagonal_block(v) {
                    Some(d) => Matrix3::from_fn(|r, c| d[r][c]),
                    None => Matrix3::from_fn(|r, c| h.get(3 * v + r, 3 * v + c)),
                };
                b.try_inverse().unwrap_or_else(|| {
                    // A singular block (no stiffness at the vertex): scale by its diagonal.
                    Matrix3::from_diagonal(&Vector3::from_fn(|i, _| {
                        let d = b[(i, i)].abs();
                        if d > 0.0 { 1.0 / d } else { 1.0 }
                    }))
                })
            })
            .collect();
        Self { inv }
    }

    fn apply(&self, r: &[f64], z: &mut [f64]) {
        for (v, m) in self.inv.iter().enumerate() {
            let x = m * Vector3::new(r[3 * v], r[3 * v + 1], r[3 * v + 2]);
            z[3 * v..3 * v + 3].copy_from_slice(x.as_slice());
        }
    }
}

/// What [`minimize`] did.
#[derive(Debug, Clone, Default)]
pub(crate) struct KrylovReport {
    pub newton_iterations: usize,
    pub cg_iterations: usize,
    pub line_search_halvings: usize,
    pub initial_residual: f64,
    pub residual: f64,
    pub energy: f64,
    pub residual_history: Vec<f64>,
}

/// Armijo constant and the most step halvings before a step is given up.
const ARMIJO: f64 = 1e-4;
const MAX_HALVINGS: usize = 40;
/// CG iterations per Newton step, at most.
const MAX_CG: usize = 500;

/// Minimises `Σ terms` from `x` until the largest gradient entry is at most `tolerance`;
/// `hessian` holds the terms' pattern; `force_scale` (N) sets CG's forcing term. Fails with weft-sim's `NotConverged` after
/// `max_iterations` Newton steps or when no step decreases the energy.
pub(crate) fn minimize(
    terms: &[&dyn Energy],
    hessian: &mut SymmetricMatrix,
    x: &mut [f64],
    tolerance: f64,
    max_iterations: usize,
    force_scale: f64,
) -> weft_sim::Result<KrylovReport> {
    let n = x.len();
    let mut grad = vec![0.0; n];
    total_gradient(terms, x, &mut grad);
    let residual_of = |g: &[f64]| weft_linalg::max_abs(g.iter().copied());
    let mut report = KrylovReport {
        initial_residual: residual_of(&grad),
        ..KrylovReport::default()
    };
    let mut residual = report.initial_residual;
    let mut energy = total_value(terms, x);
    let mut dir = vec![0.0; n];
    let mut trial = vec![0.0; n];
    while residual > tolerance {
        if report.newton_iterations >= max_iterations {
            return Err(weft_sim::Error::NotConverged {
                iterations: report.newton_iterations,
                residual,
                tolerance,
            });
        }
        report.newton_iterations += 1;
        hessian.set_zero();
        let project = residual > 1e4 * tolerance;
        for t in terms {
            t.add_hessian(x, project, hessian);
        }
        let m = BlockJacobi::new(hessian);
        // Floored so CG is never asked for more than round-off.
        let eta = (residual / force_scale).sqrt().clamp(1e-10, 0.5);
        let neg: Vec<f64> = grad.iter().map(|g| -g).collect();
        let its = pcg(hessian, |r, z| m.apply(r, z), &neg, &mut dir, eta, MAX_CG).iterations;
        report.cg_iterations += its;
        let slope = dot(&dir, &grad);
        if !(slope < 0.0) {
            // Round-off made the direction ascend: fall back to the negative gradient.
            dir.copy_from_slice(&neg);
        }
        let slope = dot(&dir, &grad);
        let mut alpha = 1.0;
        let mut accepted = None;
        for _ in 0..=MAX_HALVINGS {
            for i in 0..n {
                trial[i] = x[i] + alpha * dir[i];
            }
            let e = total_value(terms, &trial);
            if e.is_finite() && e - energy <= ARMIJO * alpha * slope {
                accepted = Some(e);
                break;
            }
            alpha *= 0.5;
            report.line_search_halvings += 1;
        }
        // Near the minimiser the energy's round-off hides the decrease; then accept the
        // full step if it lowers the residual force (as weft-sim's Newton does).
        let e = match accepted {
            Some(e) => e,
            None => {
                for i in 0..n {
                    trial[i] = x[i] + dir[i];
                }
                total_gradient(terms, &trial, &mut grad);
                if residual_of(&grad) < residual {
                    total_value(terms, &trial)
                } else {
                    return Err(weft_sim::Error::NotConverged {
                        iterations: report.newton_iterations,
                        residual,
                        tolerance,
                    });
                }
            }
        };
        x.copy_from_slice(&trial);
        energy = e;
        total_gradient(terms, x, &mut grad);
        residual = residual_of(&grad);
        if !residual.is_finite() {
            return Err(weft_sim::Error::NonFinite {
                what: "gradient",
                dof: grad.iter().position(|g| !g.is_finite()).unwrap_or(0),
            });
        }
        report.residual_history.push(residual);
    }
    report.residual = residual;
    report.energy = energy;
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use weft_linalg::SymmetricPattern;

    #[test]
    fn block_jacobi_inverts_each_diagonal_block_and_ignores_the_coupling() {
        // Two vertices: diagonal blocks [[4, 1, 0], [1, 3, 0], [0, 0, 2]] and 5I, coupled by −I.
        let pattern = std::sync::Arc::new(SymmetricPattern::from_vertex_pairs(2, [(0, 1)]));
        let mut h = SymmetricMatrix::zeros(pattern);
        for (i, d) in [4.0, 3.0, 2.0, 5.0, 5.0, 5.0].into_iter().enumerate() {
            h.add(i, i, d);
        }
        h.add(0, 1, 1.0);
        for c in 0..3 {
            h.add(c, 3 + c, -1.0);
        }
        let m = BlockJacobi::new(&h);
        let r = [1.0, 2.0, 4.0, 5.0, -10.0, 0.0];
        let mut z = [0.0; 6];
        m.apply(&r, &mut z);
        // [[4, 1], [1, 3]]⁻¹ (1, 2) = (1/11, 7/11); 4/2; (5, −10, 0)/5.
        let expected = [1.0 / 11.0, 7.0 / 11.0, 2.0, 1.0, -2.0, 0.0];
        for (a, b) in z.iter().zip(&expected) {
            assert!((a - b).abs() < 1e-12, "{z:?}");
        }
    }
}
