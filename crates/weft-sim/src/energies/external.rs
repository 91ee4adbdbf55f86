//! Inertia, gravity and other external forces, and zero-length springs to targets.

use weft_linalg::SymmetricMatrix;

use crate::energy::{Energy, vertex};
use crate::error::{Error, Result, check_nonnegative, check_positive};

/// Zero-length springs pulling each vertex to a target: `E = ½ Σ_i w_i ‖x_i − t_i‖²`
/// (weights in N/m). Used for inertia, for attachment to a network's prediction (Geng et
/// al. Eq. 12) and for soft pins.
#[derive(Debug, Clone)]
pub struct ZeroLengthSprings {
    name: &'static str,
    weights: Vec<f64>,
    targets: Vec<f64>,
}

impl ZeroLengthSprings {
    pub fn new(name: &'static str, weights: Vec<f64>, targets: Vec<f64>) -> Result<Self> {
        if targets.len() != 3 * weights.len() {
            return Err(Error::LengthMismatch {
                what: "spring targets",
                expected: 3 * weights.len(),
                got: targets.len(),
            });
        }
        for &w in &weights {
            check_nonnegative("zero-length spring weight", w)?;
        }
        Ok(Self { name, weights, targets })
    }
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }
    pub fn targets(&self) -> &[f64] {
        &self.targets
    }
    pub fn set_targets(&mut self, targets: &[f64]) -> Result<()> {
        if targets.len() != self.targets.len() {
            return Err(Error::LengthMismatch {
                what: "spring targets",
                expected: self.targets.len(),
                got: targets.len(),
            });
        }
        self.targets.copy_from_slice(targets);
        Ok(())
    }
    pub fn set_weights(&mut self, weights: &[f64]) -> Result<()> {
        if weights.len() != self.weights.len() {
            return Err(Error::LengthMismatch {
                what: "spring weights",
                expected: self.weights.len(),
                got: weights.len(),
            });
        }
        self.weights.copy_from_slice(weights);
        Ok(())
    }
}

impl Energy for ZeroLengthSprings {
    fn name(&self) -> &'static str {
        self.name
    }
    fn num_dofs(&self) -> Option<usize> {
        Some(self.targets.len())
    }
    fn hessian_pairs(&self, _pairs: &mut Vec<(usize, usize)>) {}
    fn value(&self, x: &[f64]) -> f64 {
        self.weights
            .iter()
            .enumerate()
            .map(|(i, w)| 0.5 * w * (vertex(x, i) - vertex(&self.targets, i)).norm_squared())
            .sum()
    }
    fn add_gradient(&self, x: &[f64], grad: &mut [f64]) {
        for (i, w) in self.weights.iter().enumerate() {
            for k in 0..3 {
                grad[3 * i + k] += w * (x[3 * i + k] - self.targets[3 * i + k]);
            }
        }
    }
    fn add_hessian(&self, _x: &[f64], _project: bool, hessian: &mut SymmetricMatrix) {
        for (i, w) in self.weights.iter().enumerate() {
            for k in 0..3 {
                hessian.add(3 * i + k, 3 * i + k, *w);
            }
        }
    }
}

/// The inertia term of optimisation-based implicit Euler (Tan et al. Eq. 4):
/// `‖x − 2p_{m−1} + p_{m−2}‖²_M / (2Δt²)`, i.e. zero-length springs of stiffness
/// `m_i/Δt²` to the inertial prediction `y = 2p_{m−1} − p_{m−2}`.
#[derive(Debug, Clone)]
pub struct Inertia {
    springs: ZeroLengthSprings,
    masses: Vec<f64>,
    dt: f64,
}

impl Inertia {
    /// Lumped `masses` (kg) and time step `dt` (s); the history starts at rest at `x0`.
    pub fn new(masses: Vec<f64>, dt: f64, x0: &[f64]) -> Result<Self> {
        check_positive("time step", dt)?;
        let weights = masses.iter().map(|m| m / (dt * dt)).collect();
        let springs = ZeroLengthSprings::new("inertia", weights, x0.to_vec())?;
        Ok(Self { springs, masses, dt })
    }
    pub fn dt(&self) -> f64 {
        self.dt
    }
    pub fn masses(&self) -> &[f64] {
        &self.masses
    }
    /// Sets the history `p_{m−1}`, `p_{m−2}`.
    pub fn set_history(&mut self, prev1: &[f64], prev2: &[f64]) -> Result<()> {
        if prev1.len() != prev2.len() {
            return Err(Error::LengthMismatch {
                what: "history frames",
                expected: prev1.len(),
                got: prev2.len(),
            });
        }
        let y: Vec<f64> = prev1.iter().zip(prev2).map(|(a, b)| 2.0 * a - b).collect();
        self.springs.set_targets(&y)
    }
    /// The inertial prediction `2p_{m−1} − p_{m−2}`.
    pub fn prediction(&self) -> &[f64] {
        self.springs.targets()
    }
}

impl Energy for Inertia {
    fn name(&self) -> &'static str {
        "inertia"
    }
    fn num_dofs(&self) -> Option<usize> {
        Some(3 * self.masses.len())
    }
    fn hessian_pairs(&self, _pairs: &mut Vec<(usize, usize)>) {}
    fn value(&self, x: &[f64]) -> f64 {
        self.springs.value(x)
    }
    fn add_gradient(&self, x: &[f64], grad: &mut [f64]) {
        self.springs.add_gradient(x, grad)
    }
    fn add_hessian(&self, x: &[f64], project: bool, hessian: &mut SymmetricMatrix) {
        self.springs.add_hessian(x, project, hessian)
    }
}

/// A constant force per vertex (N): `E = −Σ_i f_i · x_i`. Gravity is
/// `f_i = m_i g` ([`ConstantForce::gravity`]).
#[derive(Debug, Clone)]
pub struct ConstantForce {
    name: &'static str,
    forces: Vec<f64>,
}

impl ConstantForce {
    pub fn new(name: &'static str, forces: Vec<f64>) -> Result<Self> {
        if let Some(i) = forces.iter().position(|f| !f.is_finite()) {
            return Err(Error::NonFinite {
                what: "external force",
                dof: i,
            });
        }
        Ok(Self { name, forces })
    }
    /// Gravity `m_i g` with acceleration `g` (m/s²).
    pub fn gravity(masses: &[f64], g: [f64; 3]) -> Result<Self> {
        Self::new("gravity", masses.iter().flat_map(|m| g.map(|gk| m * gk)).collect())
    }
    pub fn forces(&self) -> &[f64] {
        &self.forces
    }
}

impl Energy for ConstantForce {
    fn name(&self) -> &'static str {
        self.name
    }
    fn num_dofs(&self) -> Option<usize> {
        Some(self.forces.len())
    }
    fn value_change(&self, from: &[f64], to: &[f64]) -> f64 {
        -self
            .forces
            .iter()
            .zip(from.iter().zip(to))
            .map(|(f, (a, b))| f * (b - a))
            .sum::<f64>()
    }
    fn is_affine(&self) -> bool {
        true
    }
    fn hessian_pairs(&self, _pairs: &mut Vec<(usize, usize)>) {}
    fn value(&self, x: &[f64]) -> f64 {
        -self.forces.iter().zip(x).map(|(f, x)| f * x).sum::<f64>()
    }
    fn add_gradient(&self, _x: &[f64], grad: &mut [f64]) {
        grad.iter_mut().zip(&self.forces).for_each(|(g, f)| *g -= f);
    }
    fn add_hessian(&self, _x: &[f64], _project: bool, _hessian: &mut SymmetricMatrix) {}
}
