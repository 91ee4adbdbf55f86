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

#[cfg(test)]
mod tests {
    use super::max_abs;

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
}
