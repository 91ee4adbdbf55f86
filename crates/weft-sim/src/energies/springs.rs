//! Linear springs `E = ½ k (‖x_a − x_b‖ − L)²`: mass-spring cloth (Tan et al. Fig. 1c,
//! after Liu et al. 2013 / Choi & Ko 2002) and the edge and bending springs of the
//! quasistatic projection layer (Geng et al. §5).

use nalgebra::{Matrix3, Vector3};
use weft_linalg::SymmetricMatrix;
use weft_mesh::{Topology, TriMesh};

use crate::energy::{Energy, vertex};
use crate::error::{Error, Result, check_nonnegative};

/// A set of springs between vertex pairs with rest lengths (m) and stiffnesses (N/m).
#[derive(Debug, Clone)]
pub struct Springs {
    name: &'static str,
    pairs: Vec<[usize; 2]>,
    rest: Vec<f64>,
    stiffness: Vec<f64>,
}

impl Springs {
    pub fn new(name: &'static str, pairs: Vec<[usize; 2]>, rest: Vec<f64>, stiffness: Vec<f64>) -> Result<Self> {
        if rest.len() != pairs.len() {
            return Err(Error::LengthMismatch {
                what: "spring rest lengths",
                expected: pairs.len(),
                got: rest.len(),
            });
        }
        if stiffness.len() != pairs.len() {
            return Err(Error::LengthMismatch {
                what: "spring stiffnesses",
                expected: pairs.len(),
                got: stiffness.len(),
            });
        }
        for (&l, &k) in rest.iter().zip(&stiffness) {
            check_nonnegative("spring rest length", l)?;
            check_nonnegative("spring stiffness", k)?;
        }
        Ok(Self {
            name,
            pairs,
            rest,
            stiffness,
        })
    }

    /// Springs on `pairs` at their lengths in `rest_positions`, all of stiffness `k`.
    pub fn at_rest(
        name: &'static str,
        rest_positions: &[Vector3<f64>],
        pairs: Vec<[usize; 2]>,
        k: f64,
    ) -> Result<Self> {
        let n = rest_positions.len();
        if let Some(&[a, b]) = pairs.iter().find(|p| p[0] >= n || p[1] >= n) {
            return Err(Error::VertexOutOfRange {
                what: "spring",
                index: a.max(b),
                num_vertices: n,
            });
        }
        let rest = pairs
            .iter()
            .map(|&[a, b]| (rest_positions[a] - rest_positions[b]).norm())
            .collect();
        let count = pairs.len();
        Self::new(name, pairs, rest, vec![k; count])
    }

    /// Stretch springs on every mesh edge (the 1-ring), stiffness `k` (N/m).
    pub fn stretch(mesh: &TriMesh, topology: &Topology, k: f64) -> Result<Self> {
        Self::at_rest("stretch springs", mesh.positions(), topology.edges.clone(), k)
    }

    /// Bending springs between every vertex and its 2-ring (each pair once), stiffness
    /// `k` (N/m) — Tan et al. Fig. 1c.
    pub fn bend_two_ring(mesh: &TriMesh, topology: &Topology, k: f64) -> Result<Self> {
        let pairs = (0..mesh.num_vertices())
            .flat_map(|i| {
                topology
                    .two_ring
                    .neighbors(i)
                    .iter()
                    .filter(move |&&j| i < j)
                    .map(move |&j| [i, j])
            })
            .collect();
        Self::at_rest("bend springs", mesh.positions(), pairs, k)
    }

    pub fn pairs(&self) -> &[[usize; 2]] {
        &self.pairs
    }
    pub fn rest_lengths(&self) -> &[f64] {
        &self.rest
    }
    pub fn stiffness(&self) -> &[f64] {
        &self.stiffness
    }
    /// Multiplies every stiffness by `factor` (Tan et al.'s 0.1·P_s, 0.1·P_b variants).
    pub fn scale_stiffness(&mut self, factor: f64) {
        self.stiffness.iter_mut().for_each(|k| *k *= factor);
    }

    /// The `3 × 3` block `K` of spring `s` (the local Hessian is `[[K, −K], [−K, K]]`):
    /// `k (d̂d̂ᵀ + (1 − L/l)(I − d̂d̂ᵀ))`. Projection clamps the transverse eigenvalue
    /// `k(1 − L/l)`, negative under compression, to zero — exact PSD projection.
    fn block(&self, s: usize, x: &[f64], project: bool) -> Matrix3<f64> {
        let [a, b] = self.pairs[s];
        let d = vertex(x, a) - vertex(x, b);
        let l = d.norm();
        let k = self.stiffness[s];
        if l <= 1e-300 {
            // Coincident endpoints: direction undefined; the isotropic limit keeps the
            // matrix bounded (and PSD when projected).
            return if project {
                Matrix3::zeros()
            } else {
                -k * (self.rest[s] > 0.0) as i32 as f64 * Matrix3::identity()
            };
        }
        let dd = d * d.transpose() / (l * l);
        let mut t = 1.0 - self.rest[s] / l;
        if project {
            t = t.max(0.0);
        }
        k * (dd + t * (Matrix3::identity() - dd))
    }
}

impl Energy for Springs {
    fn name(&self) -> &'static str {
        self.name
    }
    fn hessian_pairs(&self, pairs: &mut Vec<(usize, usize)>) {
        pairs.extend(self.pairs.iter().map(|&[a, b]| (a, b)));
    }
    fn value(&self, x: &[f64]) -> f64 {
        (0..self.pairs.len())
            .map(|s| {
                let [a, b] = self.pairs[s];
                let l = (vertex(x, a) - vertex(x, b)).norm();
                0.5 * self.stiffness[s] * (l - self.rest[s]).powi(2)
            })
            .sum()
    }
    fn add_gradient(&self, x: &[f64], grad: &mut [f64]) {
        for s in 0..self.pairs.len() {
            let [a, b] = self.pairs[s];
            let d = vertex(x, a) - vertex(x, b);
            let l = d.norm();
            if l <= 1e-300 {
                continue;
            }
            let f = self.stiffness[s] * (l - self.rest[s]) / l * d;
            for k in 0..3 {
                grad[3 * a + k] += f[k];
                grad[3 * b + k] -= f[k];
            }
        }
    }
    fn add_hessian(&self, x: &[f64], project: bool, hessian: &mut SymmetricMatrix) {
        // The local Hessian is [[K, −K], [−K, K]] with K symmetric: three vertex blocks,
        // no 6 × 6 to build and scatter.
        for s in 0..self.pairs.len() {
            let [a, b] = self.pairs[s];
            if a == b {
                continue; // a spring from a vertex to itself: constant energy
            }
            let k = self.block(s, x, project);
            let block: [[f64; 3]; 3] = k.into();
            hessian.add_vertex_block(a, a, &block);
            hessian.add_vertex_block(b, b, &block);
            let neg = block.map(|row| row.map(|v| -v));
            hessian.add_vertex_block(a.min(b), a.max(b), &neg);
        }
    }
}
