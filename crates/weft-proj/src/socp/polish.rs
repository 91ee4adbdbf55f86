//! The active-set polish: Newton's method on the KKT conditions of the edges at their
//! bound (Geng et al. Eq. 2), started from an interior-point iterate, so they hold to
//! round-off; and the conic KKT residuals that judge it.

use super::*;

impl InextensibilityLayer {
    /// Relative stationarity `‖Kδ + Aᵀz‖∞ / max(‖Kδ‖∞, ‖Aᵀz‖∞)` and relative
    /// complementarity `max_e |s_eᵀz_e| / (s_e⁰ max z⁰)` in solver units.
    pub(super) fn kkt_residuals(&self, x: &[f64], s: &[f64], z: &[f64]) -> (f64, f64) {
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

    /// Whether the backward pass keeps the conic pair `(s_e, z_e)` as a constraint row:
    /// `2 z⁰ > γ` (`γ = (s⁰² − ‖s¹‖²)/s⁰`), i.e. eliminating it would add a stiffness
    /// `2z⁰/γ` above the mean weight `k̄ = 1`. Either choice is exact; this one keeps the
    /// system well conditioned.
    pub(super) fn is_active(s: &[f64], z: &[f64]) -> bool {
        let (s0, z0) = (s[0], z[0]);
        if !(z0 > 0.0 && s0 > 0.0) {
            return false;
        }
        let s1n = (s[1] * s[1] + s[2] * s[2] + s[3] * s[3]).sqrt();
        2.0 * z0 > ((s0 - s1n) * (s0 + s1n) / s0).max(0.0)
    }

    /// Polishes the interior-point solution: Newton's method on the KKT conditions of
    /// Eq. 2 restricted to the active edges (`‖d_e‖ = l_e^max`), so the returned point
    /// satisfies them to round-off rather than to the interior-point tolerance.
    /// Accepted only if it converges with non-negative multipliers and every other edge
    /// within its bound; returns the polished point, or `None` if it was rejected.
    pub(super) fn polish(&self, b: &[f64], x: &[f64], s: &[f64], z: &[f64]) -> Option<Polished> {
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
        // The initial active set: edges whose relative multiplier exceeds their relative
        // slack, `z⁰/max z⁰ > threshold · γ/s⁰`. Scale-free on purpose: the absolute test
        // `2z⁰ > γ` of the backward pass compares a multiplier with the mean weight, and
        // under heavy stretch (multipliers far above it) it called every edge active —
        // more rows than a nearly flat sheet has in-plane freedoms, a singular system.
        let z0_max = (0..m).map(|e| z[4 * e]).fold(0.0f64, f64::max);
        let guess = |e: usize, threshold: f64| {
            let (s0, z0) = (s[4 * e], z[4 * e]);
            if !(z0 > 0.0 && s0 > 0.0) {
                return false;
            }
            let s1n = (s[4 * e + 1].powi(2) + s[4 * e + 2].powi(2) + s[4 * e + 3].powi(2)).sqrt();
            let gamma = ((s0 - s1n) * (s0 + s1n) / s0).max(0.0);
            z0 / z0_max > threshold * gamma / s0
        };
        let mut active: Vec<bool> = (0..m).map(|e| guess(e, 1.0)).collect();
        let mut start: (Vec<f64>, Vec<f64>) = (x.to_vec(), (0..m).map(|e| z[4 * e]).collect());
        let mut total = 0;
        // A primal active-set loop around Newton: the interior-point solution's active
        // set is nearly always right; an edge that needs a negative multiplier is
        // released, one that ends up over its bound is added. Each round starts from the
        // previous round's Newton solution, which differs only near the changed edges.
        // The rounds share one system over the candidate edges — ten times below the
        // activity threshold — so that a round that adds an edge rarely needs a
        // new symbolic analysis (on the paper-size sheet every added edge was a candidate
        // when the polish started from relative gaps of 1e-3 and 1e-4).
        let candidates: Vec<bool> = (0..m).map(|e| guess(e, 0.1)).collect();
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
    pub(super) fn system_over(&self, keep: &[bool]) -> Result<Arc<EdgeSystem>> {
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
    pub(super) fn polish_newton(
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
            // After the first step Newton converges quadratically here; a residual that
            // no longer halves is at its round-off floor (the caller accepts it at
            // 1e-12) or crawling on a singular system (multipliers not unique; the
            // caller rejects it). Either way more steps only cost factorisations.
            let stalled = iterations >= 2 && tnorm > 0.5 * norm;
            if stalled && tnorm >= norm {
                break;
            }
            (delta, lambda, r, r_len, norm) = (trial, trial_lambda, tr, tr_len, tnorm);
            if stalled {
                break;
            }
        }
        Some((delta, lambda, norm, iterations))
    }

    /// The regularised LDLᵀ of the edge KKT matrix `[K + Σ D_eᵀ B_e D_e, D_eᵀ c_e;
    /// c_eᵀ D_e, σ_e]` (rows first, see `crate::kkt`).
    pub(super) fn factorize_kkt<'a>(&self, system: &'a EdgeSystem, blocks: Vec<EdgeBlock>) -> Result<KktFactor<'a>> {
        system.factorize_kkt(blocks, self.settings.ldlt_delta, self.settings.refinement_steps)
    }
}

/// Whether every edge with `needed[e]` is in `system`.
pub(super) fn covers(system: &EdgeSystem, needed: &[bool]) -> bool {
    let mut inside = vec![false; needed.len()];
    system.ids().iter().for_each(|&e| inside[e] = true);
    needed.iter().zip(&inside).all(|(&n, &i)| !n || i)
}
