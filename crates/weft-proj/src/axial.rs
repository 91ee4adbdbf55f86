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

use nalgebra::Vector3;
use weft_linalg::SymmetricMatrix;
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
