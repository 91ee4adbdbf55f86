//! ACAP⁻¹: features back to positions through the pinned Poisson system, and its
//! vector–Jacobian product (Tan et al. §IV-A, Eq. 6; docs/ACAP.md §A5).

use std::sync::Arc;

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use weft_linalg::{CholeskyFactor, CholeskySolver, SymmetricMatrix, SymmetricPattern};

use crate::error::{Error, Result};
use crate::features::{AcapFeatures, Feature, feature_log_rotation, feature_stretch};
use crate::rings::Rings;
use crate::rotation::{rotation_exp, rotation_exp_with_derivatives};

const NOT_FREE: usize = usize::MAX;

/// The Poisson pseudo-inverse `L†` of Tan et al. Eq. 6 for one rest mesh and pin set,
/// factorised once.
///
/// Positions minimise `Σ_i Σ_{j∈N(i)} c_ij ‖(p_i − p_j) − T_i (q_i − q_j)‖²` with the
/// pinned vertices P held at given positions. The normal equations are `L p = b`,
/// `L_ii = Σ_j c_ij`, `L_ij = −c_ij`, `b_i = ½ Σ_j c_ij (T_i + T_j)(q_i − q_j)`
/// (docs/ACAP.md §A5). Instead of the saddle-point system `[[L, Aᵀ], [A, 0]]` of Eq. 6 this
/// eliminates the pins — the same solution — leaving the SPD system
/// `L_FF p_F = b_F − L_FP x_P`, factorised once by sparse Cholesky and solved for
/// x, y and z together. The weights c_ij are the extractor's edge weights, so that the
/// round trip `decode(encode(p))` is exact whenever every 1-ring deforms rigidly.
#[derive(Debug, Clone)]
pub struct PoissonPseudoInverse {
    rest: Vec<Vector3<f64>>,
    rings: Rings,
    pins: Vec<usize>,
    /// Index of each vertex among the free ones, or `NOT_FREE` for a pin.
    free_index: Vec<usize>,
    free: Vec<usize>,
    factor: Option<Arc<CholeskyFactor>>,
}

/// Gradients of a scalar loss with respect to the inputs of
/// [`PoissonPseudoInverse::decode`], from [`PoissonPseudoInverse::vjp`].
#[derive(Debug, Clone, PartialEq)]
pub struct DecodeGradient {
    /// ∂loss/∂features, per vertex, in the [`Feature`] layout.
    pub features: Vec<Feature>,
    /// ∂loss/∂pin positions, in the order of the pins.
    pub pin_positions: Vec<Vector3<f64>>,
}

impl PoissonPseudoInverse {
    /// Builds and factorises `L_FF` for the rest mesh of `extractor` with `pins` held.
    ///
    /// Every connected component needs at least one pin (otherwise its translation is
    /// free and `L_FF` singular).
    pub fn new(extractor: &AcapFeatures, pins: &[usize]) -> Result<Self> {
        let n = extractor.num_vertices();
        let rings = extractor.rings().clone();
        let mut free_index = vec![0; n];
        for &pin in pins {
            if pin >= n {
                return Err(Error::PinOutOfRange { pin, num_vertices: n });
            }
            if free_index[pin] == NOT_FREE {
                return Err(Error::DuplicatePin { pin });
            }
            free_index[pin] = NOT_FREE;
        }
        check_components_pinned(&rings, &free_index)?;
        let mut free = Vec::with_capacity(n - pins.len());
        for (v, idx) in free_index.iter_mut().enumerate() {
            if *idx != NOT_FREE {
                *idx = free.len();
                free.push(v);
            }
        }
        let factor = if free.is_empty() {
            None
        } else {
            let mut pairs = Vec::new();
            for (a, &i) in free.iter().enumerate() {
                for &j in rings.neighbors(i) {
                    let b = free_index[j];
                    if b != NOT_FREE && b > a {
                        pairs.push((a, b));
                    }
                }
            }
            let pattern = Arc::new(SymmetricPattern::new(free.len(), pairs));
            let mut l_ff = SymmetricMatrix::zeros(pattern.clone());
            for (a, &i) in free.iter().enumerate() {
                for (&j, &c) in rings.neighbors(i).iter().zip(rings.weights(i)) {
                    l_ff.add(a, a, c);
                    let b = free_index[j];
                    if b != NOT_FREE && b > a {
                        l_ff.add(a, b, -c);
                    }
                }
            }
            let solver = CholeskySolver::new(pattern)?;
            Some(Arc::new(solver.factorize(&l_ff)?))
        };
        Ok(Self {
            rest: extractor.rest_positions().to_vec(),
            rings,
            pins: pins.to_vec(),
            free_index,
            free,
            factor,
        })
    }

    pub fn pins(&self) -> &[usize] {
        &self.pins
    }
    pub fn num_vertices(&self) -> usize {
        self.rest.len()
    }

    fn check_features(&self, features: &[Feature]) -> Result<()> {
        if features.len() != self.rest.len() {
            return Err(Error::LengthMismatch {
                what: "features",
                expected: self.rest.len(),
                got: features.len(),
            });
        }
        if let Some((vertex, f)) = features
            .iter()
            .enumerate()
            .find(|(_, f)| !f.iter().all(|v| v.is_finite()))
        {
            return Err(Error::NonFiniteFeature { vertex, feature: *f });
        }
        Ok(())
    }

    fn check_pin_positions(&self, pin_positions: &[Vector3<f64>]) -> Result<()> {
        if pin_positions.len() != self.pins.len() {
            return Err(Error::LengthMismatch {
                what: "pin positions",
                expected: self.pins.len(),
                got: pin_positions.len(),
            });
        }
        if let Some(index) = pin_positions.iter().position(|x| !x.iter().all(|c| c.is_finite())) {
            return Err(Error::NonFinitePin {
                index,
                vertex: self.pins[index],
            });
        }
        Ok(())
    }

    /// `T_i = exp(r_i) S_i` per vertex (Tan et al. §IV-A, steps one and two).
    pub fn deformation_gradients(&self, features: &[Feature]) -> Result<Vec<Matrix3<f64>>> {
        self.check_features(features)?;
        Ok(features
            .iter()
            .map(|f| rotation_exp(&feature_log_rotation(f)) * feature_stretch(f))
            .collect())
    }

    /// ACAP⁻¹: positions from features with the pins at `pin_positions` (Tan et al. Eq. 6).
    pub fn decode(&self, features: &[Feature], pin_positions: &[Vector3<f64>]) -> Result<Vec<Vector3<f64>>> {
        let t = self.deformation_gradients(features)?;
        self.positions_from_gradients(&t, pin_positions)
    }

    /// Decodes independent frames in parallel (rayon) with the one factorisation.
    pub fn decode_batch<F, P>(&self, frames: &[F], pin_positions: &[P]) -> Result<Vec<Vec<Vector3<f64>>>>
    where
        F: AsRef<[Feature]> + Sync,
        P: AsRef<[Vector3<f64>]> + Sync,
    {
        if frames.len() != pin_positions.len() {
            return Err(Error::LengthMismatch {
                what: "pin position sets (one per frame)",
                expected: frames.len(),
                got: pin_positions.len(),
            });
        }
        frames
            .par_iter()
            .zip(pin_positions)
            .map(|(f, x)| self.decode(f.as_ref(), x.as_ref()))
            .collect()
    }

    /// The least-squares positions for given per-vertex deformation gradients: solves
    /// `L_FF p_F = b_F − L_FP x_P` (docs/ACAP.md §A5).
    pub fn positions_from_gradients(
        &self,
        t: &[Matrix3<f64>],
        pin_positions: &[Vector3<f64>],
    ) -> Result<Vec<Vector3<f64>>> {
        if t.len() != self.rest.len() {
            return Err(Error::LengthMismatch {
                what: "deformation gradients",
                expected: self.rest.len(),
                got: t.len(),
            });
        }
        self.check_pin_positions(pin_positions)?;
        let q = &self.rest;
        let n = q.len();
        let mut p = vec![Vector3::zeros(); n];
        for (&pin, x) in self.pins.iter().zip(pin_positions) {
            p[pin] = *x;
        }
        let Some(factor) = &self.factor else {
            return Ok(p);
        };
        let nf = self.free.len();
        let mut rhs = vec![0.0; 3 * nf];
        for (a, &i) in self.free.iter().enumerate() {
            let mut b = Vector3::zeros();
            for (&j, &c) in self.rings.neighbors(i).iter().zip(self.rings.weights(i)) {
                // b_i = ½ Σ_j c_ij (T_i + T_j)(q_i − q_j)   (docs/ACAP.md §A5)
                b += (t[i] + t[j]) * (q[i] - q[j]) * (0.5 * c);
                if self.free_index[j] == NOT_FREE {
                    // − L_FP x_P
                    b += p[j] * c;
                }
            }
            for d in 0..3 {
                rhs[d * nf + a] = b[d];
            }
        }
        factor.solve_many_in_place(&mut rhs, 3);
        for (a, &i) in self.free.iter().enumerate() {
            p[i] = Vector3::new(rhs[a], rhs[nf + a], rhs[2 * nf + a]);
            if !p[i].iter().all(|v| v.is_finite()) {
                return Err(Error::NonFiniteResult { vertex: i });
            }
        }
        Ok(p)
    }

    /// The vector–Jacobian product of [`PoissonPseudoInverse::decode`]: given
    /// `grad_positions` = ∂loss/∂p (all vertices, pins included), returns ∂loss/∂features
    /// and ∂loss/∂pin positions. Reuses the factorisation (`L_FF` is symmetric, so the
    /// adjoint solve is one more solve with the same factor); no dense Jacobian is formed.
    ///
    /// With λ_F = L_FF⁻¹ p̄_F and λ_P = 0: `T̄_i = ½ Σ_j c_ij (λ_i − λ_j)(q_i − q_j)ᵀ`,
    /// `x̄_P = p̄_P + Σ_j c_Pj λ_j`, then `R̄ = T̄ Sᵀ`, `S̄ = Rᵀ T̄` and the Rodrigues
    /// derivative for r̄.
    pub fn vjp(&self, features: &[Feature], grad_positions: &[Vector3<f64>]) -> Result<DecodeGradient> {
        self.check_features(features)?;
        let n = self.rest.len();
        if grad_positions.len() != n {
            return Err(Error::LengthMismatch {
                what: "position gradients",
                expected: n,
                got: grad_positions.len(),
            });
        }
        if let Some((vertex, g)) = grad_positions
            .iter()
            .enumerate()
            .find(|(_, g)| !g.iter().all(|c| c.is_finite()))
        {
            return Err(Error::NonFinitePosition {
                vertex,
                x: g.x,
                y: g.y,
                z: g.z,
            });
        }
        let q = &self.rest;
        let mut lambda = vec![Vector3::zeros(); n];
        if let Some(factor) = &self.factor {
            let nf = self.free.len();
            let mut rhs = vec![0.0; 3 * nf];
            for (a, &i) in self.free.iter().enumerate() {
                for d in 0..3 {
                    rhs[d * nf + a] = grad_positions[i][d];
                }
            }
            factor.solve_many_in_place(&mut rhs, 3);
            for (a, &i) in self.free.iter().enumerate() {
                lambda[i] = Vector3::new(rhs[a], rhs[nf + a], rhs[2 * nf + a]);
            }
        }
        let pin_positions = self
            .pins
            .iter()
            .map(|&pin| {
                let mut g = grad_positions[pin];
                for (&j, &c) in self.rings.neighbors(pin).iter().zip(self.rings.weights(pin)) {
                    g += lambda[j] * c;
                }
                g
            })
            .collect();
        let feature_grads = (0..n)
            .into_par_iter()
            .with_min_len(256)
            .map(|i| {
                let mut t_bar = Matrix3::zeros();
                for (&j, &c) in self.rings.neighbors(i).iter().zip(self.rings.weights(i)) {
                    t_bar += (lambda[i] - lambda[j]) * (q[i] - q[j]).transpose() * (0.5 * c);
                }
                let f = &features[i];
                let (rot, d_rot) = rotation_exp_with_derivatives(&feature_log_rotation(f));
                let s = feature_stretch(f);
                let r_bar_m = t_bar * s.transpose();
                let s_bar = rot.transpose() * t_bar;
                let r_bar = Vector3::from_fn(|k, _| r_bar_m.component_mul(&d_rot[k]).sum());
                // Feature layout: (−r_z, r_y, −r_x, S11, S12, S13, S22, S23, S33).
                [
                    -r_bar.z,
                    r_bar.y,
                    -r_bar.x,
                    s_bar[(0, 0)],
                    s_bar[(0, 1)] + s_bar[(1, 0)],
                    s_bar[(0, 2)] + s_bar[(2, 0)],
                    s_bar[(1, 1)],
                    s_bar[(1, 2)] + s_bar[(2, 1)],
                    s_bar[(2, 2)],
                ]
            })
            .collect();
        Ok(DecodeGradient {
            features: feature_grads,
            pin_positions,
        })
    }
}

fn check_components_pinned(rings: &Rings, free_index: &[usize]) -> Result<()> {
    let n = rings.len();
    let mut seen = vec![false; n];
    let mut stack = Vec::new();
    for s in 0..n {
        if seen[s] {
            continue;
        }
        seen[s] = true;
        stack.push(s);
        let mut pinned = false;
        while let Some(i) = stack.pop() {
            pinned |= free_index[i] == NOT_FREE;
            for &j in rings.neighbors(i) {
                if !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        if !pinned {
            return Err(Error::UnpinnedComponent { vertex: s });
        }
    }
    Ok(())
}

/// Vertex errors of a reconstruction, absolute (metres) and relative to the reference's
/// bounding-box diagonal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReconstructionError {
    pub max: f64,
    pub rms: f64,
    pub bounding_box_diagonal: f64,
}

impl ReconstructionError {
    /// Compares `decoded` with `reference` vertex by vertex.
    pub fn between(reference: &[Vector3<f64>], decoded: &[Vector3<f64>]) -> Result<Self> {
        if reference.len() != decoded.len() {
            return Err(Error::LengthMismatch {
                what: "decoded positions",
                expected: reference.len(),
                got: decoded.len(),
            });
        }
        let (mut max, mut sum) = (0.0f64, 0.0);
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for (a, b) in reference.iter().zip(decoded) {
            let d = (a - b).norm();
            max = max.max(d);
            sum += d * d;
            lo = lo.inf(a);
            hi = hi.sup(a);
        }
        let rms = (sum / reference.len().max(1) as f64).sqrt();
        Ok(Self {
            max,
            rms,
            bounding_box_diagonal: (hi - lo).norm(),
        })
    }
    /// Largest vertex error over the bounding-box diagonal.
    pub fn max_relative(&self) -> f64 {
        self.max / self.bounding_box_diagonal
    }
    /// RMS vertex error over the bounding-box diagonal.
    pub fn rms_relative(&self) -> f64 {
        self.rms / self.bounding_box_diagonal
    }
}
