//! Preconditioned conjugate gradients on a [`SymmetricMatrix`], stopping at the first
//! direction of non-positive curvature (Nocedal & Wright, *Numerical Optimization*,
//! Alg. 7.1): the one Krylov solver of weft. weft-proj's truncated Newton–Krylov
//! minimisation solves its Newton steps with it, and weft-sim's guard estimates a
//! frame's distance from the step's minimiser by the Newton step it solves.

use crate::{SymmetricMatrix, dot};

/// How a [`pcg`] solve ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CgOutcome {
    pub iterations: usize,
    /// It stopped at a direction of non-positive curvature.
    pub negative_curvature: bool,
    /// It reached the requested relative residual.
    pub converged: bool,
}

/// Preconditioned CG for `H x = b` from `x = 0`, to `‖r‖ ≤ rel_tol ‖b‖`, with
/// `precondition(r, z)` writing `z = M⁻¹ r` for an SPD `M`.
pub fn pcg(
    h: &SymmetricMatrix,
    precondition: impl Fn(&[f64], &mut [f64]),
    b: &[f64],
    x: &mut [f64],
    rel_tol: f64,
    max_iter: usize,
) -> CgOutcome {
    let n = b.len();
    let stop = |iterations, negative_curvature, converged| CgOutcome {
        iterations,
        negative_curvature,
        converged,
    };
    x.iter_mut().for_each(|v| *v = 0.0);
    if b.iter().all(|v| *v == 0.0) {
        // x = 0 solves it exactly (the first direction would be zero, not negative).
        return stop(0, false, true);
    }
    let mut r = b.to_vec();
    let mut z = vec![0.0; n];
    precondition(&r, &mut z);
    let mut p = z.clone();
    let mut hp = vec![0.0; n];
    let mut rz = dot(&r, &z);
    let target = rel_tol * dot(b, b).sqrt();
    for k in 0..max_iter {
        h.mul_vec(&p, &mut hp);
        let curvature = dot(&p, &hp);
        if !(curvature > 0.0) {
            if k == 0 {
                // Non-positive curvature along the first direction: take the
                // preconditioned gradient (a descent direction, M being SPD).
                x.copy_from_slice(&z);
            }
            return stop(k, true, false);
        }
        let alpha = rz / curvature;
        for i in 0..n {
            x[i] += alpha * p[i];
            r[i] -= alpha * hp[i];
        }
        if dot(&r, &r).sqrt() <= target {
            return stop(k + 1, false, true);
        }
        precondition(&r, &mut z);
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
    }
    stop(max_iter, false, false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::SymmetricPattern;

    /// `z = D⁻¹ r` with `D` the absolute diagonal of `h`.
    fn jacobi(h: &SymmetricMatrix) -> impl Fn(&[f64], &mut [f64]) + '_ {
        let d: Vec<f64> = h.diagonal().map(f64::abs).collect();
        move |r, z| {
            for i in 0..r.len() {
                z[i] = r[i] / d[i];
            }
        }
    }

    #[test]
    fn pcg_solves_an_spd_system_and_reports_negative_curvature() {
        // A 2-vertex SPD matrix: diagonal blocks 4I, coupling −I.
        let pattern = std::sync::Arc::new(SymmetricPattern::from_vertex_pairs(2, [(0, 1)]));
        let mut h = SymmetricMatrix::zeros(pattern.clone());
        for i in 0..6 {
            h.add(i, i, 4.0);
        }
        for c in 0..3 {
            h.add(c, 3 + c, -1.0);
        }
        let b = [1.0, 2.0, 3.0, -1.0, 0.5, 0.0];
        let mut x = [0.0; 6];
        let out = pcg(&h, jacobi(&h), &b, &mut x, 1e-12, 50);
        assert!(!out.negative_curvature && out.converged);
        let mut hx = [0.0; 6];
        h.mul_vec(&x, &mut hx);
        for (a, b) in hx.iter().zip(&b) {
            assert!((a - b).abs() < 1e-10);
        }
        // Negate it: the first direction has negative curvature.
        let mut neg = SymmetricMatrix::zeros(pattern);
        for i in 0..6 {
            neg.add(i, i, -4.0);
        }
        let out = pcg(&neg, jacobi(&neg), &b, &mut x, 1e-12, 50);
        assert!(out.negative_curvature && !out.converged && out.iterations == 0);
    }
}
