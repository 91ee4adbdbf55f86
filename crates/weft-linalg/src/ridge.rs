//! Dense ridge least squares through the normal equations, for nested feature sets.
//!
//! Fitting `W = argmin ‖Φ W − T‖² + λ‖W‖²` for a design `Φ` (rows × features) and
//! targets `T` (rows × outputs) solves `(ΦᵀΦ + λI) W = ΦᵀT` (Hoerl & Kennard 1970).
//! [`NormalEquations`] forms `ΦᵀΦ` and `ΦᵀT` once; when the candidate models use the
//! first `k` features of one design (a filter's first `k` taps), each candidate's system
//! is the leading `k × k` block, so a grid over `k` and `λ` costs one product and one
//! small Cholesky per candidate instead of a pass over the rows each. The systems here
//! are small (tens of features) and well scaled by the ridge term, so the normal
//! equations' squared condition number is not the limit a QR would lift.

use faer::linalg::solvers::Solve;
use faer::{Accum, Mat, MatRef, Par, Side};

use crate::{Error, Result};

/// `ΦᵀΦ` and `ΦᵀT` of one least-squares problem.
#[derive(Debug, Clone)]
pub struct NormalEquations {
    gram: Mat<f64>,
    rhs: Mat<f64>,
}

impl NormalEquations {
    /// The normal equations of the row-major `design` (`rows × features`) and `targets`
    /// (`rows × outputs`).
    pub fn new(design: &[f64], targets: &[f64], rows: usize, features: usize, outputs: usize) -> Result<Self> {
        for (what, got, expected) in [
            ("design", design.len(), rows * features),
            ("targets", targets.len(), rows * outputs),
        ] {
            if got != expected {
                return Err(Error::DimensionMismatch { what, expected, got });
            }
        }
        if design.iter().chain(targets).any(|v| !v.is_finite()) {
            return Err(Error::NonFinite("least-squares data"));
        }
        // Row-major rows × n is column-major n × rows: read it as Φᵀ without a copy.
        let phi_t = MatRef::from_column_major_slice(design, features, rows);
        let t_t = MatRef::from_column_major_slice(targets, outputs, rows);
        let mut gram = Mat::zeros(features, features);
        let mut rhs = Mat::zeros(features, outputs);
        // Sequential: callers fit many small systems and parallelise over them.
        faer::linalg::matmul::matmul(gram.as_mut(), Accum::Replace, phi_t, phi_t.transpose(), 1.0, Par::Seq);
        faer::linalg::matmul::matmul(rhs.as_mut(), Accum::Replace, phi_t, t_t.transpose(), 1.0, Par::Seq);
        Ok(Self { gram, rhs })
    }

    pub fn features(&self) -> usize {
        self.gram.nrows()
    }

    pub fn outputs(&self) -> usize {
        self.rhs.ncols()
    }

    /// The mean of the first `k` diagonal entries of `ΦᵀΦ`: the mean squared feature,
    /// the scale a ridge weight is usually stated relative to.
    pub fn mean_diagonal(&self, k: usize) -> f64 {
        let k = k.min(self.features());
        if k == 0 {
            return 0.0;
        }
        (0..k).map(|i| self.gram[(i, i)]).sum::<f64>() / k as f64
    }

    /// The ridge solution on the first `k` features, `(ΦₖᵀΦₖ + λI) W = ΦₖᵀT`, row-major
    /// `k × outputs`. `λ = 0` is ordinary least squares, an error when `Φₖ` is rank
    /// deficient.
    pub fn solve(&self, k: usize, lambda: f64) -> Result<Vec<f64>> {
        if k == 0 || k > self.features() {
            return Err(Error::DimensionMismatch {
                what: "leading features",
                expected: self.features(),
                got: k,
            });
        }
        if !(lambda.is_finite() && lambda >= 0.0) {
            return Err(Error::NonFinite("ridge weight"));
        }
        let mut a = self.gram.as_ref().submatrix(0, 0, k, k).to_owned();
        for i in 0..k {
            a[(i, i)] += lambda;
        }
        let llt = a.llt(Side::Lower).map_err(|_| Error::NotPositiveDefinite)?;
        let w = llt.solve(self.rhs.as_ref().subrows(0, k));
        let m = self.outputs();
        let out: Vec<f64> = (0..k)
            .flat_map(|i| (0..m).map(move |j| (i, j)))
            .map(|(i, j)| w[(i, j)])
            .collect();
        if out.iter().any(|v| !v.is_finite()) {
            return Err(Error::NonFinite("ridge solution"));
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_exact_linear_target_is_recovered_and_the_ridge_shrinks_it() {
        // t = 2 φ₀ − 3 φ₁ exactly; the third feature is noise the fit must ignore.
        let design = [1.0, 0.0, 0.5, 0.0, 1.0, -0.5, 1.0, 1.0, 0.25, 2.0, -1.0, 0.0];
        let targets: Vec<f64> = design.chunks(3).map(|r| 2.0 * r[0] - 3.0 * r[1]).collect();
        let ne = NormalEquations::new(&design, &targets, 4, 3, 1).unwrap();
        let w = ne.solve(3, 0.0).unwrap();
        for (w, e) in w.iter().zip([2.0, -3.0, 0.0]) {
            assert!((w - e).abs() < 1e-12, "{w} vs {e}");
        }
        // One feature, by hand: w = Σφ₀t / (Σφ₀² + λ) with φ₀ = 1, 0, 1, 2 and
        // t = 2, −3, −1, 7: Σφ₀t = 2 − 1 + 14 = 15, Σφ₀² = 6.
        assert!((ne.solve(1, 0.0).unwrap()[0] - 15.0 / 6.0).abs() < 1e-12);
        assert!((ne.solve(1, 4.0).unwrap()[0] - 15.0 / 10.0).abs() < 1e-12);
        assert!((ne.mean_diagonal(2) - (6.0 + 3.0) / 2.0).abs() < 1e-12);
    }

    #[test]
    fn a_rank_deficient_design_needs_the_ridge() {
        // Two identical columns: ΦᵀΦ is singular, the ridge splits the weight evenly.
        let design = [1.0, 1.0, 2.0, 2.0];
        let ne = NormalEquations::new(&design, &[3.0, 6.0], 2, 2, 1).unwrap();
        assert!(matches!(
            ne.solve(2, 0.0),
            Err(Error::NotPositiveDefinite) | Err(Error::NonFinite(_))
        ));
        let w = ne.solve(2, 1e-9).unwrap();
        assert!((w[0] - 1.5).abs() < 1e-6 && (w[1] - 1.5).abs() < 1e-6, "{w:?}");
        assert!(ne.solve(3, 1.0).is_err());
        assert!(NormalEquations::new(&design, &[3.0], 2, 2, 1).is_err());
    }
}
