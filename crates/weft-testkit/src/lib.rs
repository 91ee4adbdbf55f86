//! Test support shared by weft's crates: explicit-tolerance float comparison and
//! finite-difference derivative checks.
//!
//! This crate is a dev-dependency only. It is not a numerics library: the checks here
//! are deliberately simple (central differences, fixed steps) so that a failing test
//! points at the code under test, not at the checker.
//!
//! ```
//! use weft_testkit::{assert_close, fd_gradient};
//! let f = |x: &[f64]| x[0] * x[0] + 3.0 * x[1];
//! let g = fd_gradient(f, &[2.0, 1.0], 1e-6);
//! assert_close!(g[0], 4.0, rtol = 1e-8, atol = 1e-8);
//! assert_close!(g[1], 3.0, rtol = 1e-8, atol = 1e-8);
//! ```

/// `|a - b| <= atol + rtol * max(|a|, |b|)`, false for any NaN.
pub fn is_close(a: f64, b: f64, rtol: f64, atol: f64) -> bool {
    if !(a.is_finite() && b.is_finite()) {
        return a == b;
    }
    (a - b).abs() <= atol + rtol * a.abs().max(b.abs())
}

/// Asserts two floats agree to an explicit tolerance: `assert_close!(a, b, rtol = 1e-9, atol = 1e-12)`.
#[macro_export]
macro_rules! assert_close {
    ($a:expr, $b:expr, rtol = $rtol:expr, atol = $atol:expr $(,)?) => {{
        let (a, b): (f64, f64) = ($a as f64, $b as f64);
        assert!(
            $crate::is_close(a, b, $rtol, $atol),
            "assert_close failed: {} = {a:e}, {} = {b:e}, |diff| = {:e} (rtol {:e}, atol {:e})",
            stringify!($a),
            stringify!($b),
            (a - b).abs(),
            $rtol,
            $atol
        );
    }};
}

/// Largest violation ratio of `|a_i - b_i| / (atol + rtol * max|.|)` over two slices
/// compared with a *norm-relative* tolerance: entries are compared against
/// `atol + rtol * max_j |b_j|`, which is the right measure for gradients whose
/// individual entries may cross zero.
pub fn max_norm_rel_error(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len(), "slices of different lengths");
    // NaN or ∞ anywhere makes the error +∞, so an all-NaN analytic result fails.
    let scale = weft_linalg::max_abs(b.iter().chain(a.iter()).copied());
    let diff = weft_linalg::max_abs(a.iter().zip(b).map(|(x, y)| x - y));
    if !(scale.is_finite() && diff.is_finite()) {
        return f64::INFINITY;
    }
    if scale == 0.0 { diff } else { diff / scale }
}

/// Central-difference gradient of a scalar function.
pub fn fd_gradient(f: impl Fn(&[f64]) -> f64, x: &[f64], h: f64) -> Vec<f64> {
    let mut xp = x.to_vec();
    (0..x.len())
        .map(|i| {
            xp[i] = x[i] + h;
            let fp = f(&xp);
            xp[i] = x[i] - h;
            let fm = f(&xp);
            xp[i] = x[i];
            (fp - fm) / (2.0 * h)
        })
        .collect()
}

/// Central-difference Jacobian-vector product `J v` of a vector function.
pub fn fd_directional(f: impl Fn(&[f64]) -> Vec<f64>, x: &[f64], v: &[f64], h: f64) -> Vec<f64> {
    let xp: Vec<f64> = x.iter().zip(v).map(|(a, b)| a + h * b).collect();
    let xm: Vec<f64> = x.iter().zip(v).map(|(a, b)| a - h * b).collect();
    let fp = f(&xp);
    let fm = f(&xm);
    fp.iter().zip(&fm).map(|(p, m)| (p - m) / (2.0 * h)).collect()
}

/// Central-difference Jacobian (rows = outputs, columns = inputs), dense. For tests on
/// small problems only.
pub fn fd_jacobian(f: impl Fn(&[f64]) -> Vec<f64>, x: &[f64], h: f64) -> Vec<Vec<f64>> {
    let n = x.len();
    let mut cols = Vec::with_capacity(n);
    let mut e = vec![0.0; n];
    for i in 0..n {
        e[i] = 1.0;
        cols.push(fd_directional(&f, x, &e, h));
        e[i] = 0.0;
    }
    let m = cols.first().map_or(0, Vec::len);
    (0..m).map(|r| cols.iter().map(|c| c[r]).collect()).collect()
}

/// A small deterministic pseudo-random generator so tests need no extra dependency and
/// give the same numbers on every machine: weft's one SplitMix64 (`weft_linalg::SplitMix64`,
/// the generator the simulations draw from), with a helper for vectors.
#[derive(Debug, Clone)]
pub struct TestRng(weft_linalg::SplitMix64);

impl TestRng {
    pub fn new(seed: u64) -> Self {
        Self(weft_linalg::SplitMix64::new(seed))
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }
    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.0.uniform(lo, hi)
    }
    /// A vector of `n` uniforms in `[lo, hi)`.
    pub fn vec(&mut self, n: usize, lo: f64, hi: f64) -> Vec<f64> {
        (0..n).map(|_| self.uniform(lo, hi)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fd_gradient_of_quadratic_is_exact() {
        let f = |x: &[f64]| x[0] * x[0] * x[1] + x[1].sin();
        let g = fd_gradient(f, &[0.7, -1.3], 1e-6);
        assert_close!(g[0], 2.0 * 0.7 * -1.3, rtol = 1e-7, atol = 1e-9);
        assert_close!(g[1], 0.49 + (-1.3f64).cos(), rtol = 1e-7, atol = 1e-9);
    }

    #[test]
    fn is_close_rejects_nan_and_large_differences() {
        assert!(!is_close(f64::NAN, 1.0, 1.0, 1.0));
        assert!(!is_close(1.0, 1.1, 1e-3, 1e-3));
        assert!(is_close(1.0, 1.0 + 1e-12, 1e-9, 0.0));
    }

    #[test]
    fn rng_is_deterministic_and_in_range() {
        let mut a = TestRng::new(7);
        let mut b = TestRng::new(7);
        for _ in 0..100 {
            let x = a.uniform(-2.0, 3.0);
            assert_eq!(x, b.uniform(-2.0, 3.0));
            assert!((-2.0..3.0).contains(&x));
        }
    }
}
