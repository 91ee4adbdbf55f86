//! Axial zero-length bending springs (Geng et al. §5, Fig. 6; Selle et al. 2008):
//! for every hinge, a point on the shared edge `(a, b)` is tied to a point on the
//! fictitious bending edge `(c, d)` between the two opposite vertices,
//!
//! `E_axial = Σ ½ k ‖(1 − u) r_a + u r_b − (1 − v) r_c − v r_d‖²`,
//!
//! with `u, v` the closest-point parameters of the two edges' lines in the rest state (for
//! a flat rest state they cross, so the spring has zero rest length; a curved rest state
//! is biased toward flat, as in the paper, which considers flat rest states only). It keeps
//! the tetrahedron of a hinge from collapsing flat-to-degenerate, which the edge and
//! bending springs alone allow near a flat rest state. The energy is quadratic with a
//! constant positive semi-definite Hessian `k w wᵀ ⊗ I₃`, `w = [1−u, u, −(1−v), −v]`.

use std::sync::Arc;

use nalgebra::Vector3;
use weft_linalg::{SymmetricMatrix, SymmetricPattern};
use weft_sim::Energy;
use weft_sim::energy::{element_pairs, vertex};

use crate::error::{Error, Result};
use crate::rest::RestShape;

/// The axial springs of every hinge of a rest mesh.
#[derive(Debug, Clone)]
pub struct AxialSprings {
    /// `[a, b, c, d]`: shared edge `(a, b)`, bending edge `(c, d)`.
    quads: Vec<[usize; 4]>,
    /// `[1 − u, u, −(1 − v), −v]` per spring.
    weights: Vec<[f64; 4]>,
    stiffness: f64,
}

impl AxialSprings {
    /// One spring per hinge of `rest` (hinges whose two opposite vertices coincide are
    /// skipped), stiffness `k` (N/m).
    pub fn new(rest: &RestShape, k: f64) -> Result<Self> {
        if !(k.is_finite() && k >= 0.0) {
            return Err(Error::InvalidParameter {
                name: "axial stiffness",
                value: k,
                reason: "must be finite and ≥ 0",
            });
        }
        let p = rest.rest_positions();
        let mut quads = Vec::new();
        let mut weights = Vec::new();
        for h in &rest.topology().hinges {
            let [a, b] = h.edge_vertices;
            let [c, d] = h.opposite;
            if c == d {
                continue;
            }
            let (u, v) = closest_parameters(&p[a], &p[b], &p[c], &p[d]);
            quads.push([a, b, c, d]);
            weights.push([1.0 - u, u, -(1.0 - v), -v]);
        }
        Ok(Self {
            quads,
            weights,
            stiffness: k,
        })
    }

    pub fn len(&self) -> usize {
        self.quads.len()
    }
    pub fn is_empty(&self) -> bool {
        self.quads.is_empty()
    }
    pub fn quads(&self) -> &[[usize; 4]] {
        &self.quads
    }

    /// The constant Hessian `Σ k w wᵀ ⊗ I₃` on `pattern` (which must hold the quads' pairs),
    /// assembled once so that Newton steps add it slot by slot ([`AxialWithHessian`]):
    /// two thirds of a step's block assembly are these sixteen blocks per hinge.
    pub(crate) fn hessian(&self, pattern: Arc<SymmetricPattern>) -> SymmetricMatrix {
        let mut h = SymmetricMatrix::zeros(pattern);
        let x = vec![0.0; h.dim()];
        self.add_hessian(&x, false, &mut h);
        h
    }

    fn gap(&self, s: usize, x: &[f64]) -> Vector3<f64> {
        let (q, w) = (&self.quads[s], &self.weights[s]);
        (0..4).map(|j| w[j] * vertex(x, q[j])).sum()
    }
}

/// Closest-point parameters `(u, v)` of the *lines* through `p0p1` and `q0q1`. In a flat
/// rest state the lines of a hinge's shared and bending edges meet, so the spring has zero
/// rest length even where the crossing lies at or just beyond a segment's end (a
/// non-convex or degenerate quad, as on a jittered grid). Parallel lines fall back to the
/// segment midpoints.
fn closest_parameters(p0: &Vector3<f64>, p1: &Vector3<f64>, q0: &Vector3<f64>, q1: &Vector3<f64>) -> (f64, f64) {
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, f) = (d1.norm_squared(), d2.norm_squared(), d2.dot(&r));
    let (b, c) = (d1.dot(&d2), d1.dot(&r));
    let denom = a * e - b * b;
    if !(denom > 1e-12 * a * e) {
        return (0.5, 0.5);
    }
    ((b * f - c * e) / denom, (a * f - b * c) / denom)
}

impl Energy for AxialSprings {
    fn name(&self) -> &'static str {
        "axial bending springs"
    }
    fn hessian_pairs(&self, pairs: &mut Vec<(usize, usize)>) {
        for q in &self.quads {
            element_pairs(q, pairs);
        }
    }
    fn value(&self, x: &[f64]) -> f64 {
        (0..self.quads.len())
            .map(|s| 0.5 * self.stiffness * self.gap(s, x).norm_squared())
            .sum()
    }
    fn add_gradient(&self, x: &[f64], grad: &mut [f64]) {
        for s in 0..self.quads.len() {
            let g = self.stiffness * self.gap(s, x);
            for (j, &v) in self.quads[s].iter().enumerate() {
                for k in 0..3 {
                    grad[3 * v + k] += self.weights[s][j] * g[k];
                }
            }
        }
    }
    fn add_hessian(&self, _x: &[f64], _project: bool, hessian: &mut SymmetricMatrix) {
        // k w wᵀ ⊗ I₃ is already positive semi-definite: projection changes nothing.
        // One 3 × 3 block per vertex pair (`add_vertex_block` keeps the stored upper
        // triangle, so every ordered pair is offered).
        for (q, w) in self.quads.iter().zip(&self.weights) {
            for i in 0..4 {
                for j in 0..4 {
                    let h = self.stiffness * w[i] * w[j];
                    let block = [[h, 0.0, 0.0], [0.0, h, 0.0], [0.0, 0.0, h]];
                    hessian.add_vertex_block(q[i], q[j], &block);
                }
            }
        }
    }
}

/// [`AxialSprings`] with their Hessian precomputed ([`AxialSprings::hessian`]): value and
/// gradient as the springs', the Hessian added slot by slot where the target matrix has
/// the precomputed one's structure (assembled block by block otherwise).
#[derive(Debug, Clone, Copy)]
pub(crate) struct AxialWithHessian<'a> {
    pub springs: &'a AxialSprings,
    pub hessian: &'a SymmetricMatrix,
}

impl Energy for AxialWithHessian<'_> {
    fn name(&self) -> &'static str {
        self.springs.name()
    }
    fn hessian_pairs(&self, pairs: &mut Vec<(usize, usize)>) {
        self.springs.hessian_pairs(pairs)
    }
    fn value(&self, x: &[f64]) -> f64 {
        self.springs.value(x)
    }
    fn add_gradient(&self, x: &[f64], grad: &mut [f64]) {
        self.springs.add_gradient(x, grad)
    }
    fn add_hessian(&self, x: &[f64], project: bool, hessian: &mut SymmetricMatrix) {
        if hessian.add_matrix(self.hessian).is_err() {
            self.springs.add_hessian(x, project, hessian);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use weft_testkit::TestRng;

    #[test]
    fn the_precomputed_hessian_is_the_assembled_one_on_any_equal_pattern() {
        // The assembled Hessian does not depend on x, so the one
        // precomputed at x = 0 must equal it at any x — into a matrix over the same Arc,
        // over another Arc of an equal pattern (Newton's own), and, through the fallback,
        // over a pattern with more pairs.
        let mesh = weft_mesh::generators::sheet(6, 1.0).unwrap();
        let rest = RestShape::new(&mesh).unwrap();
        let axial = AxialSprings::new(&rest, 0.3).unwrap();
        let n = rest.num_vertices();
        let mut pairs = Vec::new();
        axial.hessian_pairs(&mut pairs);
        let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(n, pairs.iter().copied()));
        let precomputed = axial.hessian(pattern.clone());
        let term = AxialWithHessian {
            springs: &axial,
            hessian: &precomputed,
        };
        let mut rng = TestRng::new(4);
        let x = rng.vec(3 * n, -0.5, 0.5);
        let mut extra = pairs.clone();
        extra.push((0, n - 1));
        for pattern in [
            pattern.clone(),
            Arc::new(SymmetricPattern::from_vertex_pairs(n, pairs.iter().copied())),
            Arc::new(SymmetricPattern::from_vertex_pairs(n, extra)),
        ] {
            let mut assembled = SymmetricMatrix::zeros(pattern.clone());
            axial.add_hessian(&x, true, &mut assembled);
            let mut added = SymmetricMatrix::zeros(pattern);
            added.values_mut().iter_mut().for_each(|v| *v = 1.0);
            term.add_hessian(&x, true, &mut added);
            for (a, b) in assembled.values().iter().zip(added.values()) {
                assert!((a + 1.0 - b).abs() < 1e-15, "{a} + 1 against {b}");
            }
            assert!(assembled.values().iter().any(|v| *v != 0.0));
        }
        // Value and gradient are the springs' own.
        assert_eq!(term.value(&x), axial.value(&x));
        let (mut g1, mut g2) = (vec![0.0; 3 * n], vec![0.0; 3 * n]);
        term.add_gradient(&x, &mut g1);
        axial.add_gradient(&x, &mut g2);
        assert_eq!(g1, g2);
    }
}
