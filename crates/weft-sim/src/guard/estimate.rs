//! The guard's error estimate: how far a frame can be from the step's minimiser, from the
//! step's residual force and a certified lower bound on the step's curvature
//! (docs/GUARD.md, "The estimate").

use std::sync::Arc;

use weft_linalg::{SymmetricMatrix, SymmetricPattern};

use crate::energy::{Energy, checked_pairs};
use crate::error::Result;
use crate::integrators::ImplicitEuler;

/// Power iterations behind the Collatz–Wielandt bound on the negative curvature
/// (docs/GUARD.md): every iterate gives a valid bound, more only tighten it.
pub const CERTIFICATE_ITERATIONS: usize = 8;

/// What the residual at a frame says about its distance from the step's minimiser `x*`.
///
/// With `μ` the step's modulus of strong convexity in the mass metric,
/// `‖x − x*‖_M ≤ ‖∇E(x)‖_{M⁻¹} / μ` (docs/GUARD.md, Eq. G3).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ErrorEstimate {
    /// `‖∇E(x)‖_{M⁻¹}` over the free DOFs (N/√kg).
    pub residual_m_inv: f64,
    /// The largest free-DOF residual force `|∂E/∂x_i|` (N): what Newton's tolerance bounds.
    pub residual_max: f64,
    /// The certified lower bound on the modulus, `1/Δt² − ρ` (1/s²); not positive where
    /// the negative curvature `ρ` may cancel the mass term.
    pub modulus: f64,
    /// Whether the strong-convexity condition was certified at the frame (`modulus > 0`).
    /// When it was not, the estimate below uses `μ = 1/Δt²` (what it would be with a
    /// positive semi-definite elastic Hessian) and is **not** a bound.
    pub certified: bool,
    /// The estimate of `‖x − x*‖_M` (m·√kg).
    pub distance: f64,
    /// The same as a mass-weighted RMS per coordinate (mm):
    /// `1000 · distance / √(3 Σ_v m_v)`, which equals M_rms for uniform masses.
    pub mm: f64,
}

/// The per-mesh data and scratch of [`ErrorEstimate`]s for one integrator.
#[derive(Debug)]
pub(crate) struct Estimator {
    /// Mass of each DOF's vertex (kg).
    dof_mass: Vec<f64>,
    free: Vec<bool>,
    /// `√(3 Σ_v m_v)` (√kg): the mass-weighted RMS's denominator.
    rms_scale: f64,
    /// `√(Σ_free 1/m_i)` (1/√kg): `‖g‖_{M⁻¹} ≤ ‖g‖_∞ · this`.
    max_to_m_inv: f64,
    exact: SymmetricMatrix,
    projected: SymmetricMatrix,
    grad: Vec<f64>,
}

impl Estimator {
    pub(crate) fn new(integrator: &ImplicitEuler) -> Result<Self> {
        let n = integrator.positions().len();
        let terms: Vec<&dyn Energy> = integrator.terms().iter().map(|t| t.as_ref()).collect();
        let pairs = checked_pairs(n, &terms)?;
        let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(n / 3, pairs));
        let dof_mass: Vec<f64> = (0..n).map(|i| integrator.masses()[i / 3]).collect();
        let free: Vec<bool> = integrator.fixed().iter().map(|f| !f).collect();
        let total: f64 = integrator.masses().iter().sum();
        let inv: f64 = (0..n).filter(|&i| free[i]).map(|i| 1.0 / dof_mass[i]).sum();
        Ok(Self {
            dof_mass,
            free,
            rms_scale: (3.0 * total).sqrt(),
            max_to_m_inv: inv.sqrt(),
            exact: SymmetricMatrix::zeros(pattern.clone()),
            projected: SymmetricMatrix::zeros(pattern),
            grad: vec![0.0; n],
        })
    }

    /// A mass-weighted distance (m·√kg) as a mass-weighted RMS per coordinate (mm).
    pub(crate) fn to_mm(&self, distance: f64) -> f64 {
        1e3 * distance / self.rms_scale
    }

    /// The mass-weighted distance (m·√kg) of `mm`.
    pub(crate) fn distance_of_mm(&self, mm: f64) -> f64 {
        1e-3 * mm * self.rms_scale
    }

    /// The largest free-DOF residual force (N) that guarantees `‖g‖_{M⁻¹} ≤ bound`.
    pub(crate) fn max_residual_for(&self, bound: f64) -> f64 {
        bound / self.max_to_m_inv.max(f64::MIN_POSITIVE)
    }

    /// `‖a − b‖_M` over all DOFs (m·√kg).
    pub(crate) fn m_norm(&self, a: &[f64], b: &[f64]) -> f64 {
        a.iter()
            .zip(b)
            .zip(&self.dof_mass)
            .map(|((a, b), m)| m * (a - b).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// The estimate at frame `x` of the integrator's next step (its history is the
    /// integrator's current state). The residual is the integrator's own gradient of
    /// Tan et al. Eq. 4 ([`ImplicitEuler::l_phys_gradient`]).
    pub(crate) fn estimate(&mut self, integrator: &ImplicitEuler, x: &[f64]) -> Result<ErrorEstimate> {
        integrator.l_phys_gradient(
            integrator.previous_positions(),
            integrator.positions(),
            x,
            &mut self.grad,
        )?;
        let (mut sq, mut max) = (0.0f64, 0.0f64);
        for i in (0..x.len()).filter(|&i| self.free[i]) {
            let g = self.grad[i];
            sq += g * g / self.dof_mass[i];
            max = max.max(g.abs());
        }
        // NaN compares false: a non-finite gradient must not read as a zero residual.
        if !sq.is_finite() || self.grad.iter().any(|g| !g.is_finite()) {
            sq = f64::INFINITY;
            max = f64::INFINITY;
        }
        let inv_dt2 = 1.0 / integrator.dt().powi(2);
        let modulus = inv_dt2 - self.negative_curvature(integrator, x);
        let certified = modulus > 0.0;
        let residual_m_inv = sq.sqrt();
        let distance = residual_m_inv / if certified { modulus } else { inv_dt2 };
        Ok(ErrorEstimate {
            residual_m_inv,
            residual_max: max,
            modulus,
            certified,
            distance,
            mm: self.to_mm(distance),
        })
    }

    /// A certified upper bound `ρ` (1/s²) on how far the potential's Hessian at `x` bends
    /// below zero in the mass metric: `H ⪰ −ρ M` on the free DOFs.
    ///
    /// The Hessian is the sum of element Hessians `H_e`; each term's projected assembly
    /// sums their positive semi-definite projections `H_e⁺`, so `H = H⁺ + N` with
    /// `H⁺ ⪰ 0` and `N = H − H⁺`. Then `H ⪰ N ⪰ −ρ(N) I`, and in the mass metric
    /// `ρ(M^{−½} N M^{−½}) ≤ ρ(|M^{−½} N M^{−½}|) ≤ max_i (|S| d)_i / d_i` for any positive
    /// `d` (Collatz–Wielandt). A few power iterations on `|S|` make `d` close to its Perron
    /// vector, which makes the bound tight; no factorisation is needed.
    fn negative_curvature(&mut self, integrator: &ImplicitEuler, x: &[f64]) -> f64 {
        self.exact.set_zero();
        self.projected.set_zero();
        for t in integrator.terms() {
            t.add_hessian(x, false, &mut self.exact);
            t.add_hessian(x, true, &mut self.projected);
        }
        let n = x.len();
        let pattern = self.exact.pattern().clone();
        // The off-projection part |S| as (row, col, value), free DOFs only.
        let mut entries = Vec::new();
        for (slot, r, c) in pattern.entries() {
            let v = self.exact.values()[slot] - self.projected.values()[slot];
            if v != 0.0 && self.free[r] && self.free[c] {
                entries.push((r, c, v.abs() / (self.dof_mass[r] * self.dof_mass[c]).sqrt()));
            }
        }
        if entries.is_empty() {
            return 0.0;
        }
        if entries.iter().any(|e| !e.2.is_finite()) {
            return f64::INFINITY;
        }
        let mut d: Vec<f64> = self.free.iter().map(|&f| if f { 1.0 } else { 0.0 }).collect();
        let mut y = vec![0.0; n];
        let mut best = f64::INFINITY;
        for _ in 0..CERTIFICATE_ITERATIONS {
            y.iter_mut().for_each(|v| *v = 0.0);
            for &(r, c, v) in &entries {
                y[r] += v * d[c];
                if r != c {
                    y[c] += v * d[r];
                }
            }
            let bound = (0..n)
                .filter(|&i| self.free[i])
                .map(|i| y[i] / d[i])
                .fold(0.0, f64::max);
            best = best.min(bound);
            // The next `d` must stay positive on every free DOF (rows of `|S|` may be zero).
            // Normalised to a largest entry of about 1, so repeated products cannot
            // overflow or underflow.
            let scale = weft_linalg::max_abs(y.iter().copied()).max(f64::MIN_POSITIVE);
            for i in (0..n).filter(|&i| self.free[i]) {
                d[i] = y[i] / scale + 1e-6;
            }
        }
        best
    }
}
