//! Small 3 × 3 rotation math: polar decomposition, the principal logarithm, Rodrigues'
//! exponential and its derivative (docs/ACAP.md §A2 and §A5).

use nalgebra::{Matrix3, Vector3};

/// `[v]_×`, the cross-product matrix: `[v]_× u = v × u`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Polar decomposition `T = R S` with `det R = +1` and `S` symmetric (docs/ACAP.md §A2).
///
/// From the SVD `T = U Σ Vᵀ`: `R = U Vᵀ`, `S = V Σ Vᵀ`. If `det(U Vᵀ) < 0` (an inverted
/// 1-ring) the column of `U` belonging to the smallest singular value and that value are
/// negated, so `R` stays a proper rotation and `S` becomes indefinite. nalgebra's
/// `polar()` does not make this correction. Returns `None` if the SVD does not converge
/// (only possible for non-finite input).
pub fn polar_decomposition(t: &Matrix3<f64>) -> Option<(Matrix3<f64>, Matrix3<f64>)> {
    if !t.iter().all(|v| v.is_finite()) {
        return None;
    }
    let svd = t.try_svd(true, true, f64::EPSILON, 1000)?;
    let (mut u, v_t) = (svd.u?, svd.v_t?);
    let mut sigma = svd.singular_values;
    if (u * v_t).determinant() < 0.0 {
        let k = sigma.imin();
        u.column_mut(k).neg_mut();
        sigma[k] = -sigma[k];
    }
    let r = u * v_t;
    let s = v_t.transpose() * Matrix3::from_diagonal(&sigma) * v_t;
    Some((r, 0.5 * (s + s.transpose())))
}

/// The principal logarithm of a rotation as (unit axis ω, angle θ ∈ [0, π]) (docs/ACAP.md §A2).
///
/// θ comes from `atan2(‖vee(R − Rᵀ)‖/2, (tr R − 1)/2)`, accurate over the whole range.
/// For θ ≤ π/2 the axis is `vee(R − Rᵀ)` normalised; beyond, where `sin θ` loses
/// precision, it is read off `(R + Rᵀ)/2 = cos θ I + (1 − cos θ) ω ωᵀ` (the column with
/// the largest diagonal) with its sign taken from `vee(R − Rᵀ)`. At θ = π exactly both
/// signs are the same rotation; the consistency pass chooses. At θ = 0 the axis is
/// arbitrary (`e_x`).
pub fn principal_log(r: &Matrix3<f64>) -> (Vector3<f64>, f64) {
    let v = Vector3::new(r[(2, 1)] - r[(1, 2)], r[(0, 2)] - r[(2, 0)], r[(1, 0)] - r[(0, 1)]);
    let sin2 = v.norm(); // 2 sin θ
    let cos = 0.5 * (r.trace() - 1.0);
    let theta = (0.5 * sin2).atan2(cos);
    if cos >= 0.0 {
        if sin2 == 0.0 {
            return (Vector3::x(), 0.0);
        }
        return (v / sin2, theta);
    }
    let sym = 0.5 * (r + r.transpose());
    let denom = 1.0 - cos; // ≥ 1 here
    let b = (sym - Matrix3::identity() * cos) / denom; // ω ωᵀ
    let k = b.diagonal().imax();
    let mut axis: Vector3<f64> = b.column(k).into_owned();
    let n = axis.norm();
    axis /= n;
    if axis.dot(&v) < 0.0 {
        axis = -axis;
    }
    (axis, theta)
}

/// The coefficients `A = sin θ / θ`, `B = (1 − cos θ)/θ²` of Rodrigues' formula and their
/// scaled derivatives `a1 = A'(θ)/θ`, `b1 = B'(θ)/θ`, with Taylor series near θ = 0.
fn rodrigues_coefficients(theta2: f64) -> (f64, f64, f64, f64) {
    if theta2 < 1e-4 {
        // θ < 1e-2: truncation error O(θ⁶) < 1e-12.
        let t2 = theta2;
        let t4 = t2 * t2;
        (
            1.0 - t2 / 6.0 + t4 / 120.0,
            0.5 - t2 / 24.0 + t4 / 720.0,
            -1.0 / 3.0 + t2 / 30.0 - t4 / 840.0,
            -1.0 / 12.0 + t2 / 180.0 - t4 / 6720.0,
        )
    } else {
        let t = theta2.sqrt();
        let (s, c) = t.sin_cos();
        let a = s / t;
        let b = (1.0 - c) / theta2;
        let a1 = (t * c - s) / (theta2 * t);
        let b1 = (t * s - 2.0 * (1.0 - c)) / (theta2 * theta2);
        (a, b, a1, b1)
    }
}

/// Rodrigues' formula `exp([r]_×) = I + A K + B K²`, `K = [r]_×` (docs/ACAP.md §A5; Tan et
/// al. §IV-A, first step of ACAP⁻¹).
pub fn rotation_exp(r: &Vector3<f64>) -> Matrix3<f64> {
    let (a, b, _, _) = rodrigues_coefficients(r.norm_squared());
    let k = skew(r);
    Matrix3::identity() + k * a + k * k * b
}

/// `exp([r]_×)` and its three partial derivatives `∂R/∂r_k`.
///
/// With `K = [r]_×`, `E_k = [e_k]_×`: `∂R/∂r_k = a1 r_k K + A E_k + b1 r_k K² + B (E_k K + K E_k)`.
pub fn rotation_exp_with_derivatives(r: &Vector3<f64>) -> (Matrix3<f64>, [Matrix3<f64>; 3]) {
    let (a, b, a1, b1) = rodrigues_coefficients(r.norm_squared());
    let k = skew(r);
    let k2 = k * k;
    let rot = Matrix3::identity() + k * a + k2 * b;
    let d = std::array::from_fn(|i| {
        let e = skew(&Vector3::ith(i, 1.0));
        k * (a1 * r[i]) + e * a + k2 * (b1 * r[i]) + (e * k + k * e) * b
    });
    (rot, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use weft_testkit::{TestRng, assert_close};

    fn random_rotation_vector(rng: &mut TestRng, max_angle: f64) -> Vector3<f64> {
        let axis = Vector3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)).normalize();
        axis * rng.uniform(0.0, max_angle)
    }

    #[test]
    fn log_inverts_exp_over_the_principal_range_including_near_pi() {
        let mut rng = TestRng::new(11);
        let mut cases: Vec<Vector3<f64>> = (0..200)
            .map(|_| random_rotation_vector(&mut rng, std::f64::consts::PI))
            .collect();
        cases.push(Vector3::new(0.0, 0.0, std::f64::consts::PI - 1e-9));
        cases.push(Vector3::new(1e-9, 0.0, 0.0));
        cases.push(Vector3::new(0.3, -0.2, 0.1).normalize() * (std::f64::consts::PI - 1e-5));
        for r in cases {
            let (axis, theta) = principal_log(&rotation_exp(&r));
            assert_close!(axis.norm(), 1.0, rtol = 0.0, atol = 1e-12);
            let back = axis * theta;
            assert!(
                (back - r).norm() < 1e-9 * (1.0 + r.norm()),
                "log(exp({r:?})) = {back:?}"
            );
        }
    }

    #[test]
    fn log_of_identity_is_zero_and_of_half_turn_is_pi() {
        let (_, theta) = principal_log(&Matrix3::identity());
        assert_eq!(theta, 0.0);
        let half = rotation_exp(&(Vector3::new(1.0, 2.0, -2.0).normalize() * std::f64::consts::PI));
        let (axis, theta) = principal_log(&half);
        assert_close!(theta, std::f64::consts::PI, rtol = 0.0, atol = 1e-12);
        let expected = Vector3::new(1.0, 2.0, -2.0).normalize();
        assert_close!(axis.dot(&expected).abs(), 1.0, rtol = 0.0, atol = 1e-12);
    }

    #[test]
    fn exp_is_a_rotation_and_series_matches_closed_form_at_the_switch() {
        let mut rng = TestRng::new(3);
        for _ in 0..50 {
            let r = random_rotation_vector(&mut rng, 7.0);
            let m = rotation_exp(&r);
            assert!((m.transpose() * m - Matrix3::identity()).norm() < 1e-13);
            assert_close!(m.determinant(), 1.0, rtol = 0.0, atol = 1e-13);
        }
        let below = rodrigues_coefficients(1e-4 * (1.0 - 1e-12));
        let above = rodrigues_coefficients(1e-4 * (1.0 + 1e-12));
        assert_close!(below.0, above.0, rtol = 1e-11, atol = 0.0);
        assert_close!(below.1, above.1, rtol = 1e-11, atol = 0.0);
        assert_close!(below.2, above.2, rtol = 1e-8, atol = 0.0);
        assert_close!(below.3, above.3, rtol = 1e-7, atol = 0.0);
    }

    #[test]
    fn exp_derivative_matches_finite_differences() {
        let mut rng = TestRng::new(5);
        let mut cases: Vec<Vector3<f64>> = (0..20).map(|_| random_rotation_vector(&mut rng, 9.0)).collect();
        cases.push(Vector3::new(1e-3, -2e-3, 5e-4));
        cases.push(Vector3::zeros());
        for r in cases {
            let (_, d) = rotation_exp_with_derivatives(&r);
            for k in 0..3 {
                let h = 1e-6;
                let e = Vector3::ith(k, h);
                let fd = (rotation_exp(&(r + e)) - rotation_exp(&(r - e))) / (2.0 * h);
                assert!(
                    (fd - d[k]).norm() < 1e-8,
                    "∂R/∂r_{k} at {r:?}: fd {fd} analytic {}",
                    d[k]
                );
            }
        }
    }

    #[test]
    fn polar_decomposition_recomposes_and_fixes_reflections() {
        let mut rng = TestRng::new(9);
        for case in 0..100 {
            let mut t = Matrix3::from_fn(|_, _| rng.uniform(-1.0, 1.0));
            if case % 2 == 0 && t.determinant() > 0.0 {
                t.column_mut(0).neg_mut();
            }
            let (r, s) = polar_decomposition(&t).expect("finite input");
            assert!((r * s - t).norm() < 1e-12 * (1.0 + t.norm()));
            assert_close!(r.determinant(), 1.0, rtol = 0.0, atol = 1e-12);
            assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-12);
            assert!((s - s.transpose()).norm() < 1e-14);
            if t.determinant() < 0.0 {
                assert!(s.determinant() < 0.0, "an inverted T must give an indefinite S");
            }
        }
        assert!(polar_decomposition(&Matrix3::from_element(f64::NAN)).is_none());
    }
}
