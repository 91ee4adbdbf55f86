//! Max-norms that see NaN. `f64::max` returns the other operand when one is NaN, so a
//! fold with it silently drops NaN entries: a residual of all NaN would read as 0 and
//! pass every convergence test. Every max-norm in weft goes through [`max_abs`], which
//! treats a non-finite entry as +∞. [`dot`] is the one plain inner product.

/// The largest `|v|` over `values`, `+∞` if any value is NaN or infinite, `0` if empty.
pub fn max_abs<I: IntoIterator<Item = f64>>(values: I) -> f64 {
    let mut m = 0.0f64;
    for v in values {
        if !v.is_finite() {
            return f64::INFINITY;
        }
        m = m.max(v.abs());
    }
    m
}

/// The Euclidean inner product of two equally long vectors.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Spearman's rank correlation of two equally long samples (ties ranked by position):
/// 1 when one orders them as the other does, −1 when reversed.
pub fn rank_correlation(a: &[f64], b: &[f64]) -> f64 {
    let ranks = |v: &[f64]| {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&i, &j| v[i].total_cmp(&v[j]));
        let mut r = vec![0.0; v.len()];
        for (rank, i) in idx.into_iter().enumerate() {
            r[i] = rank as f64;
        }
        r
    };
    let (ra, rb) = (ranks(a), ranks(b));
    let n = a.len().min(b.len()) as f64;
    let d2: f64 = ra.iter().zip(&rb).map(|(x, y)| (x - y).powi(2)).sum();
    1.0 - 6.0 * d2 / (n * (n * n - 1.0)).max(f64::MIN_POSITIVE)
}

#[cfg(test)]
mod tests {
    use super::{max_abs, rank_correlation};

    #[test]
    fn nan_and_infinity_dominate_and_signs_are_ignored() {
        assert_eq!(max_abs([1.0, -3.0, 2.0]), 3.0);
        assert_eq!(max_abs([f64::NAN, 0.0]), f64::INFINITY);
        assert_eq!(max_abs([0.0, f64::NAN]), f64::INFINITY);
        assert_eq!(max_abs([f64::NEG_INFINITY]), f64::INFINITY);
        assert_eq!(max_abs(std::iter::empty()), 0.0);
        // The pattern this replaces loses the NaN:
        assert_eq!([f64::NAN, 1.0].iter().fold(0.0f64, |m, v| m.max(v.abs())), 1.0);
    }

    #[test]
    fn rank_correlation_of_orders_same_reversed_and_one_swap() {
        let a = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(rank_correlation(&a, &[10.0, 20.0, 30.0, 40.0, 50.0]), 1.0);
        assert_eq!(rank_correlation(&a, &[5.0, 4.0, 3.0, 2.0, 1.0]), -1.0);
        // One adjacent swap: Σd² = 2, ρ = 1 − 12 / 120.
        assert!((rank_correlation(&a, &[1.0, 3.0, 2.0, 4.0, 5.0]) - 0.9).abs() < 1e-12);
    }
}
