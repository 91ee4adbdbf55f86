//! Geometric warps of linear elasticity and NNWarp's per-node inputs (Luo et al., NNWarp
//! §3 and §5).
//!
//! A linear solve gives displacements `ũ`; near each node `i` the displacement gradient
//! `G_i = ∂u/∂x̄` is fitted by least squares over the node's 1-ring (NNWarp Eq. 6:
//! `u_j − u_i ≈ G_i (x̄_j − x̄_i)`). Its skew part is an infinitesimal rotation with
//! rotation vector `w_i` (`[w_i]× = (G_i − G_iᵀ)/2`, half the curl of `u`), its symmetric
//! part the small strain `S_i`. From these:
//! - modal warping (Choi & Ko; NNWarp Eq. 4) moves each node by
//!   `W_MW ũ_i`, `W_MW = ∫₀¹ exp(s [w_i]×) ds`;
//! - rotation-strain warping (Huang et al.; NNWarp Eq. 5) forms
//!   `T_i = exp([w_i]×)(S_i + I)` per node and rebuilds positions by one global Poisson
//!   solve that makes every 1-ring edge `x_j − x_i` as close as possible to
//!   `T_i (x̄_j − x̄_i)`, the anchors held at rest (factorised once);
//! - NNWarp's network sees three rotation-invariant kinematic scalars of `(ũ_i, w_i)` in
//!   a per-node aligned frame (§5, Fig. 12) and three contextual features: geodesic
//!   distance to the anchors, potential along the force field, digression (Eq. 9).
//!
//! All of this is geometry of the linear solution, not physics: no energy is evaluated.

use std::sync::Arc;

use nalgebra::{Matrix3, Rotation3, Vector3};
use weft_linalg::{CholeskyFactor, CholeskySolver, SymmetricMatrix, SymmetricPattern};
use weft_mesh::{TetMesh, TetTopology};

use crate::error::{Error, Result};

#[inline]
fn node(x: &[f64], i: usize) -> Vector3<f64> {
    Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2])
}

/// Least-squares displacement gradients over each node's 1-ring (NNWarp Eq. 6).
///
/// The rings are stored flat (compressed rows): the correction of every frame reads them
/// node after node, so one contiguous pass beats one allocation per node.
#[derive(Debug, Clone)]
pub struct NodalGradients {
    /// Node `i`'s ring is `neighbors[offsets[i]..offsets[i + 1]]`.
    offsets: Vec<usize>,
    neighbors: Vec<usize>,
    /// `weights[k] = (P_i P_iᵀ)⁻¹ (x̄_j − x̄_i)` for the ring entry `k` of node `i` with
    /// neighbour `j`, so that `G_i = Σ_k (u_j − u_i) weights[k]ᵀ`.
    weights: Vec<Vector3<f64>>,
    /// `Σ_k weights[k]` over node `i`'s ring.
    weight_sums: Vec<Vector3<f64>>,
}

impl NodalGradients {
    /// Precomputes the fit for every node of `mesh`. A node whose 1-ring spans less than
    /// three dimensions (cannot happen in a valid tet mesh) is an error.
    pub fn new(mesh: &TetMesh) -> Result<Self> {
        let topo = TetTopology::new(mesh);
        let rest = mesh.positions();
        let mut offsets = Vec::with_capacity(rest.len() + 1);
        offsets.push(0);
        let mut neighbors = Vec::new();
        let mut weights = Vec::new();
        let mut weight_sums = Vec::with_capacity(rest.len());
        for (i, xi) in rest.iter().enumerate() {
            let ring = topo.one_ring.neighbors(i);
            let ppt: Matrix3<f64> = ring
                .iter()
                .map(|&j| {
                    let d = rest[j] - xi;
                    d * d.transpose()
                })
                .sum();
            let inv = ppt
                .try_inverse()
                .filter(|m| m.iter().all(|v| v.is_finite()))
                .ok_or(Error::InvalidParameter {
                    name: "node 1-ring",
                    value: i as f64,
                    reason: "spans fewer than three dimensions; no displacement gradient",
                })?;
            weights.extend(ring.iter().map(|&j| inv * (rest[j] - xi)));
            weight_sums.push(weights[offsets[i]..].iter().sum());
            neighbors.extend_from_slice(ring);
            offsets.push(neighbors.len());
        }
        Ok(Self {
            offsets,
            neighbors,
            weights,
            weight_sums,
        })
    }

    pub fn num_nodes(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Node `i`'s 1-ring.
    #[inline]
    pub fn ring(&self, i: usize) -> &[usize] {
        &self.neighbors[self.offsets[i]..self.offsets[i + 1]]
    }

    #[inline]
    fn ring_weights(&self, i: usize) -> &[Vector3<f64>] {
        &self.weights[self.offsets[i]..self.offsets[i + 1]]
    }

    /// `G_i` of the flat displacements `u` (3 per node).
    pub fn gradient(&self, u: &[f64], i: usize) -> Matrix3<f64> {
        let ui = node(u, i);
        self.ring(i)
            .iter()
            .zip(self.ring_weights(i))
            .map(|(&j, c)| (node(u, j) - ui) * c.transpose())
            .sum()
    }

    /// `rotation_vector(&self.gradient(u, i))` without forming `G_i`: the skew part of
    /// `Σ_k d_k c_kᵀ` (`d_k = u_j − u_i`) has rotation vector
    /// `½ Σ_k c_k × d_k = ½ (Σ_k c_k × u_j − (Σ_k c_k) × u_i)`. NNWarp's runtime needs only
    /// this, every frame at every node.
    #[inline]
    pub fn rotation_vector(&self, u: &[f64], i: usize) -> Vector3<f64> {
        let ring: Vector3<f64> = self
            .ring(i)
            .iter()
            .zip(self.ring_weights(i))
            .map(|(&j, c)| c.cross(&node(u, j)))
            .sum();
        0.5 * (ring - self.weight_sums[i].cross(&node(u, i)))
    }

    /// Every node's rotation vector `w_i` (see [`NodalGradients::rotation_vector`]).
    pub fn rotation_vectors(&self, u: &[f64]) -> Result<Vec<Vector3<f64>>> {
        self.check(u)?;
        Ok((0..self.num_nodes()).map(|i| self.rotation_vector(u, i)).collect())
    }

    /// Every node's `G_i`.
    pub fn gradients(&self, u: &[f64]) -> Result<Vec<Matrix3<f64>>> {
        self.check(u)?;
        Ok((0..self.num_nodes()).map(|i| self.gradient(u, i)).collect())
    }

    fn check(&self, u: &[f64]) -> Result<()> {
        if u.len() != 3 * self.num_nodes() {
            return Err(Error::LengthMismatch {
                what: "nodal displacements",
                expected: 3 * self.num_nodes(),
                got: u.len(),
            });
        }
        if let Some(dof) = u.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "nodal displacement",
                dof,
            });
        }
        Ok(())
    }
}

/// The rotation vector `w` of `G`'s skew part: `[w]× = (G − Gᵀ)/2`.
pub fn rotation_vector(g: &Matrix3<f64>) -> Vector3<f64> {
    0.5 * Vector3::new(g[(2, 1)] - g[(1, 2)], g[(0, 2)] - g[(2, 0)], g[(1, 0)] - g[(0, 1)])
}

/// `G`'s symmetric part, the small strain `S = (G + Gᵀ)/2`.
pub fn small_strain(g: &Matrix3<f64>) -> Matrix3<f64> {
    0.5 * (g + g.transpose())
}

/// Modal warping's matrix `∫₀¹ exp(s [w]×) ds = I + (1 − cos θ)/θ² [w]× + (θ − sin θ)/θ³ [w]×²`
/// (θ = |w|; NNWarp Eq. 4 with t = 1), by its series below θ = 1e-4.
pub fn modal_warp_matrix(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta = w.norm();
    let k = w.cross_matrix();
    let (a, b) = if theta < 1e-4 {
        let t2 = theta * theta;
        (0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0)
    } else {
        let t2 = theta * theta;
        ((1.0 - theta.cos()) / t2, (theta - theta.sin()) / (t2 * theta))
    };
    Matrix3::identity() + a * k + b * k * k
}

/// Modal warping (NNWarp Eq. 4): `u_i = W_MW(w_i) ũ_i` at every node.
pub fn modal_warp(gradients: &NodalGradients, linear: &[f64]) -> Result<Vec<f64>> {
    let g = gradients.gradients(linear)?;
    Ok(g.iter()
        .enumerate()
        .flat_map(|(i, g)| {
            let u = modal_warp_matrix(&rotation_vector(g)) * node(linear, i);
            [u.x, u.y, u.z]
        })
        .collect())
}

/// Each node's load seen in its rest frame, `R_iᵀ f_i` with `R_i = exp([w_i]×)` the local
/// rotation of displacements `u`: stiffness warping's treatment of external forces
/// (Müller et al. 2002), which NNWarp's runtime adopts (§6). Eq. 7 trains the network on
/// shapes with `f_int(u) = 𝓡 K ũ`; when the linear solve is `K ũ = 𝓡ᵀ f`, that target
/// is `f_int(u) = f`, the nonlinear equilibrium under the actual load.
pub fn loads_in_rest_frames(gradients: &NodalGradients, u: &[f64], forces: &[f64]) -> Result<Vec<f64>> {
    if forces.len() != u.len() {
        return Err(Error::LengthMismatch {
            what: "forces",
            expected: u.len(),
            got: forces.len(),
        });
    }
    rotate_loads_to_rest(&gradients.rotation_vectors(u)?, forces)
}

/// [`loads_in_rest_frames`] with each node's rotation vector `w_i` already known (NNWarp's
/// correction fits the same gradients; its runtime passes them on instead of fitting
/// them twice).
pub fn rotate_loads_to_rest(rotation_vectors: &[Vector3<f64>], forces: &[f64]) -> Result<Vec<f64>> {
    if forces.len() != 3 * rotation_vectors.len() {
        return Err(Error::LengthMismatch {
            what: "forces (3 per rotation vector)",
            expected: 3 * rotation_vectors.len(),
            got: forces.len(),
        });
    }
    let mut out = forces.to_vec();
    for (i, w) in rotation_vectors.iter().enumerate() {
        let theta = w.norm();
        if theta == 0.0 {
            continue;
        }
        // Rodrigues for `exp([w]×)ᵀ f`, without forming the matrix (this runs at every
        // node of every NNWarp frame).
        let k = w / theta;
        let (sin, cos) = theta.sin_cos();
        let f = node(forces, i);
        let local = cos * f - sin * k.cross(&f) + ((1.0 - cos) * k.dot(&f)) * k;
        out[3 * i..3 * i + 3].copy_from_slice(local.as_slice());
    }
    Ok(out)
}

/// NNWarp's linear regime (§6), the one solve its runtime and its training ramp share:
/// each frame's load is turned into every node's rest frame by the local rotations of the
/// previous frame's linear displacement ([`rotate_loads_to_rest`]), then one solve with
/// the pre-factorised system. Only then is Eq. 7's target `f_int(u) = 𝓡 K ũ` the body
/// under the actual load (up to the one-frame lag of the rotations and, in a dynamic
/// solve, the inertia and damping forces): a ramp registered from the plain solve
/// `K ũ = f` would train the network on shapes under follower loads, `f_int(u) = 𝓡 f`,
/// that the runtime never asks for (issue 70).
#[derive(Debug)]
pub struct RestFrameSolve {
    linear: crate::PrefactorizedLinear,
    /// The previous frame's rotation vectors `w_i` (zero at rest).
    rotations: Vec<Vector3<f64>>,
}

impl RestFrameSolve {
    /// Starts at rest: the first frame's load is not rotated.
    pub fn new(linear: crate::PrefactorizedLinear) -> Self {
        let nodes = linear.displacements().len() / 3;
        Self {
            linear,
            rotations: vec![Vector3::zeros(); nodes],
        }
    }

    pub fn linear(&self) -> &crate::PrefactorizedLinear {
        &self.linear
    }

    /// One frame under the world-frame `load`: rotated by the last rotations
    /// ([`RestFrameSolve::set_rotations`]), then solved. Returns the linear displacements.
    pub fn step(&mut self, load: &[f64]) -> Result<&[f64]> {
        let load = rotate_loads_to_rest(&self.rotations, load)?;
        self.linear.step(&load, &[])?;
        Ok(self.linear.displacements())
    }

    /// The rotation vectors of the frame just solved, for the next frame's load. The
    /// runtime passes the ones its correction fitted (zero at the anchors, whose loads the
    /// solve ignores); the training ramp fits them with [`NodalGradients::rotation_vectors`].
    pub fn set_rotations(&mut self, rotations: Vec<Vector3<f64>>) -> Result<()> {
        if rotations.len() != self.rotations.len() {
            return Err(Error::LengthMismatch {
                what: "rotation vectors (one per node)",
                expected: self.rotations.len(),
                got: rotations.len(),
            });
        }
        self.rotations = rotations;
        Ok(())
    }
}

/// How [`warped_static_solve`] ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarpedStaticReport {
    /// Linear solves done (the first, unrotated one included).
    pub solves: usize,
    /// `max |ũ_k − ũ_{k−1}| / max |ũ_k|` of the last iteration.
    pub change: f64,
    /// The relaxation factor the iteration ended with (1 = plain fixed-point iteration).
    pub relaxation: f64,
}

/// The static stiffness-warped linear displacement: the fixed point of
/// `ũ = K⁻¹ 𝓡(ũ)ᵀ f` (see [`loads_in_rest_frames`]), iterated from `ũ = K⁻¹ f` with the
/// pre-factorised `K` of `linear` (static mode) until successive answers differ by at most
/// `tolerance` of their largest entry. Leaves the answer in `linear.displacements()`.
///
/// Each iteration solves for the relaxed load `h ← (1 − ω) h + ω 𝓡(ũ)ᵀ f` (so `ũ` moves
/// by the fraction `ω` of the plain iteration's step, `K` being linear). `ω` starts at 1
/// and halves whenever the change fails to shrink: where the rotations swing with the
/// displacement (a body hanging from interior anchors), the plain iteration oscillates.
/// A fixed point not reached within `max_solves` solves is [`Error::WarpNotSettled`].
pub fn warped_static_solve(
    linear: &mut crate::PrefactorizedLinear,
    gradients: &NodalGradients,
    forces: &[f64],
    tolerance: f64,
    max_solves: usize,
) -> Result<WarpedStaticReport> {
    if linear.mode() != crate::LinearSolve::Static {
        return Err(Error::NotStatic);
    }
    linear.step(forces, &[])?;
    let mut load = forces.to_vec();
    let (mut change, mut relaxation) = (f64::INFINITY, 1.0f64);
    for solves in 2..=max_solves {
        let previous = linear.displacements().to_vec();
        let rotated = loads_in_rest_frames(gradients, &previous, forces)?;
        for (h, g) in load.iter_mut().zip(&rotated) {
            *h += relaxation * (g - *h);
        }
        linear.step(&load, &[])?;
        let u = linear.displacements();
        let largest = weft_linalg::max_abs(u.iter().copied());
        let diff = u.iter().zip(&previous).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        let next = if largest > 0.0 { diff / largest } else { 0.0 };
        if next <= tolerance {
            return Ok(WarpedStaticReport {
                solves,
                change: next,
                relaxation,
            });
        }
        if next >= change {
            relaxation = (0.5 * relaxation).max(1.0 / 64.0);
        }
        change = next;
    }
    if max_solves <= 1 {
        return Ok(WarpedStaticReport {
            solves: 1,
            change,
            relaxation,
        });
    }
    Err(Error::WarpNotSettled {
        solves: max_solves,
        change,
    })
}

/// Rotation-strain warping (NNWarp Eq. 5) with its Poisson reconstruction, the graph
/// Laplacian of the 1-rings factorised once with the anchors eliminated.
#[derive(Debug)]
pub struct RotationStrainWarp {
    gradients: Arc<NodalGradients>,
    rest: Vec<Vector3<f64>>,
    anchored: Vec<bool>,
    /// `(free row, anchor, L_ra)`: the couplings to anchors that the elimination drops
    /// from the matrix and the solve moves to the right-hand side.
    anchor_couplings: Vec<(usize, usize, f64)>,
    factor: CholeskyFactor,
}

impl RotationStrainWarp {
    /// `anchored[i]`: node `i` stays at rest (the Dirichlet boundary). At least one node
    /// must be anchored, or the reconstruction is defined only up to a translation.
    pub fn new(mesh: &TetMesh, gradients: Arc<NodalGradients>, anchored: Vec<bool>) -> Result<Self> {
        let n = mesh.num_vertices();
        if anchored.len() != n || gradients.num_nodes() != n {
            return Err(Error::LengthMismatch {
                what: "anchor mask",
                expected: n,
                got: anchored.len(),
            });
        }
        if !anchored.iter().any(|a| *a) {
            return Err(Error::InvalidParameter {
                name: "anchors",
                value: 0.0,
                reason: "rotation-strain warping needs at least one anchored node",
            });
        }
        let pairs: Vec<(usize, usize)> = (0..n)
            .flat_map(|i| gradients.ring(i).iter().map(move |&j| (i, j)))
            .collect();
        let pattern = Arc::new(SymmetricPattern::new(n, pairs.iter().copied()));
        let mut laplacian = SymmetricMatrix::zeros(pattern.clone());
        // Each directed 1-ring pair (i, j) adds |x_j − x_i − T_i d_ij|² (j's ring holds i
        // too, so an undirected edge counts twice, in the matrix and in the right-hand side).
        for &(i, j) in &pairs {
            laplacian.add(i, i, 1.0);
            laplacian.add(j, j, 1.0);
            if i < j {
                laplacian.add(i, j, -2.0);
            }
        }
        let anchor_couplings = pattern
            .entries()
            .filter(|&(_, r, c)| anchored[r] != anchored[c])
            .map(|(slot, r, c)| {
                let v = laplacian.values()[slot];
                if anchored[c] { (r, c, v) } else { (c, r, v) }
            })
            .collect();
        laplacian.constrain_dofs(&anchored);
        let factor = CholeskySolver::new(pattern)?.factorize(&laplacian)?;
        Ok(Self {
            gradients,
            rest: mesh.positions().to_vec(),
            anchored,
            anchor_couplings,
            factor,
        })
    }

    /// The warped displacements of the linear displacements `linear`.
    pub fn warp(&self, linear: &[f64]) -> Result<Vec<f64>> {
        let g = self.gradients.gradients(linear)?;
        let n = self.rest.len();
        let transforms: Vec<Matrix3<f64>> = g
            .iter()
            .map(|g| {
                let r = Rotation3::from_scaled_axis(rotation_vector(g));
                r.matrix() * (small_strain(g) + Matrix3::identity())
            })
            .collect();
        // Column-major right-hand sides, one per coordinate.
        let mut rhs = vec![0.0; 3 * n];
        for i in 0..n {
            for &j in self.gradients.ring(i) {
                let e = transforms[i] * (self.rest[j] - self.rest[i]);
                for d in 0..3 {
                    rhs[d * n + j] += e[d];
                    rhs[d * n + i] -= e[d];
                }
            }
        }
        for &(row, anchor, value) in &self.anchor_couplings {
            for d in 0..3 {
                rhs[d * n + row] -= value * self.rest[anchor][d];
            }
        }
        for i in (0..n).filter(|&i| self.anchored[i]) {
            for d in 0..3 {
                rhs[d * n + i] = self.rest[i][d];
            }
        }
        self.factor.solve_many_in_place(&mut rhs, 3);
        Ok((0..n)
            .flat_map(|i| [0, 1, 2].map(|d| rhs[d * n + i] - self.rest[i][d]))
            .collect())
    }
}

/// NNWarp §5's alignment (Fig. 12): the rotation `Q` that takes `ũ` to the +y axis and
/// then, about y, the part of `w` orthogonal to `ũ` to the −x axis; and the three
/// rotation-invariant scalars left, `(|ũ|, w·û, |w − (w·û)û|)`. Below `1e-12` of a
/// unit the undefined directions are taken as the identity's.
#[inline]
pub fn aligned_kinematics(u: &Vector3<f64>, w: &Vector3<f64>) -> (Rotation3<f64>, [f64; 3]) {
    let tiny = 1e-12;
    let un = u.norm();
    if un > tiny {
        // The common case, without trigonometry: a rotation is fixed by the images of two
        // orthonormal vectors, û ↦ +y and p̂ ↦ −x (p = w's part orthogonal to û), so its
        // rows are −p̂, û and −p̂ × û. The same rotation as the two-step construction below.
        let uh = u / un;
        let along = w.dot(&uh);
        let p = w - uh * along;
        let pn = p.norm();
        if pn > tiny {
            let r1 = -p / pn;
            let r3 = r1.cross(&uh);
            let m = nalgebra::Matrix3::from_rows(&[r1.transpose(), uh.transpose(), r3.transpose()]);
            return (Rotation3::from_matrix_unchecked(m), [un, along, pn]);
        }
    }
    let first = if un > tiny {
        Rotation3::rotation_between(u, &Vector3::y()).unwrap_or_else(|| {
            // ũ along −y: half a turn about x.
            Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        })
    } else {
        Rotation3::identity()
    };
    let w1 = first * w;
    let perp = Vector3::new(w1.x, 0.0, w1.z);
    let second = if perp.norm() > tiny {
        // The rotation about +y taking `perp` to −x.
        let angle = perp.z.atan2(-perp.x);
        Rotation3::from_axis_angle(&Vector3::y_axis(), -angle)
    } else {
        Rotation3::identity()
    };
    let q = second * first;
    (q, [un, w1.y, perp.norm()])
}

/// The scale and centre that fit `positions` into the unit sphere about their bounding
/// box's centre (NNWarp §3.3 trains on the body scaled this way).
pub fn unit_sphere_normalization(positions: &[Vector3<f64>]) -> (Vector3<f64>, f64) {
    let (lo, hi) = positions.iter().fold(
        (Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.inf(p), hi.sup(p)),
    );
    let center = (lo + hi) / 2.0;
    let radius = positions.iter().map(|p| (p - center).norm()).fold(0.0f64, f64::max);
    (center, if radius > 0.0 { 1.0 / radius } else { 1.0 })
}

/// The force field a sample was driven by, as the contextual features see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FieldDirection {
    /// A directional field along this (non-zero) vector.
    Directional(Vector3<f64>),
    /// A circular field about the axis through `center` along `axis`.
    Circular { center: Vector3<f64>, axis: Vector3<f64> },
}

/// NNWarp §3.3's contextual features per node: geodesic `g` (graph distance to the
/// nearest anchor over the largest, in [0, 1]), potential `p` (directional field: the rest
/// position's projection on the field direction, mapped to [0, 1]; circular field: the
/// distance to the axis over the largest), digression `d` (Eq. 9: the angle between
/// `x̄_i − x̄_a`, `a` the Euclidean-nearest anchor, and the field direction, in [0, π];
/// −1 for a circular field; 0 at the anchors themselves). All three are invariant to a
/// uniform scaling of the body.
pub fn contextual_features(mesh: &TetMesh, anchors: &[usize], field: FieldDirection) -> Result<Vec<[f64; 3]>> {
    let rest = mesh.positions();
    if anchors.is_empty() {
        return Err(Error::InvalidParameter {
            name: "anchors",
            value: 0.0,
            reason: "the contextual features need at least one anchored node",
        });
    }
    let topo = TetTopology::new(mesh);
    let geodesic = weft_mesh::geodesic::geodesic_distances(rest, &topo.one_ring, anchors)?;
    let g_max = geodesic
        .iter()
        .copied()
        .filter(|d| d.is_finite())
        .fold(0.0f64, f64::max);
    if geodesic.iter().any(|d| !d.is_finite()) {
        return Err(Error::InvalidParameter {
            name: "anchors",
            value: anchors.len() as f64,
            reason: "some nodes are not connected to any anchor",
        });
    }
    let unit = |v: Vector3<f64>, what: &'static str| -> Result<Vector3<f64>> {
        let n = v.norm();
        if n.is_finite() && n > 0.0 {
            Ok(v / n)
        } else {
            Err(Error::InvalidParameter {
                name: what,
                value: n,
                reason: "must be a non-zero finite vector",
            })
        }
    };
    let (potential, digression): (Vec<f64>, Vec<f64>) = match field {
        FieldDirection::Directional(dir) => {
            let e = unit(dir, "force direction")?;
            let proj: Vec<f64> = rest.iter().map(|p| p.dot(&e)).collect();
            let (lo, hi) = proj
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)));
            let span = if hi > lo { hi - lo } else { 1.0 };
            let digression = rest
                .iter()
                .map(|p| {
                    let a = anchors
                        .iter()
                        .map(|&k| rest[k])
                        .min_by(|x, y| (x - p).norm().total_cmp(&(y - p).norm()))
                        .unwrap_or(*p);
                    let d = p - a;
                    if d.norm() > 0.0 {
                        (d.normalize().dot(&e)).clamp(-1.0, 1.0).acos()
                    } else {
                        0.0
                    }
                })
                .collect();
            (proj.iter().map(|v| (v - lo) / span).collect(), digression)
        }
        FieldDirection::Circular { center, axis } => {
            let a = unit(axis, "circular field axis")?;
            let dist: Vec<f64> = rest
                .iter()
                .map(|p| {
                    let d = p - center;
                    (d - a * a.dot(&d)).norm()
                })
                .collect();
            let max = dist.iter().copied().fold(0.0f64, f64::max);
            let scale = if max > 0.0 { 1.0 / max } else { 1.0 };
            (dist.iter().map(|d| d * scale).collect(), vec![-1.0; rest.len()])
        }
    };
    let g_scale = if g_max > 0.0 { 1.0 / g_max } else { 1.0 };
    Ok((0..rest.len())
        .map(|i| [geodesic[i] * g_scale, potential[i], digression[i]])
        .collect())
}

/// NNWarp Eq. 6–7: the nonlinear displacement `u` registered to a linear one `ũ`, the
/// solution of `f_int(u) = 𝓡 K ũ` where `𝓡` rotates each node's linear internal force by
/// its local rotation `exp([w_i]×)` of `ũ`. It is found as the minimiser of
/// `E(x̄ + u) − (𝓡Kũ)·u` (the equation is that energy's stationarity condition) by
/// weft-sim's Newton solver, started from the previous registration: registering a
/// sequence in order follows one branch of equilibria, which is the point of registering
/// sequences rather than single poses (NNWarp Fig. 2). The paper imposes Wolfe
/// conditions on its Newton steps; our solver's Armijo backtracking from the full Newton
/// step gives the same guarantee of decrease.
#[derive(Debug)]
pub struct Registration {
    gradients: Arc<NodalGradients>,
    stiffness: SymmetricMatrix,
    elastic: crate::energies::TetElasticity,
    solver: crate::newton::NewtonSolver,
    rest: Vec<f64>,
    /// The last registered positions (the next solve's start).
    x: Vec<f64>,
    /// Newton's residual tolerance relative to the largest target force component.
    pub relative_tolerance: f64,
}

impl Registration {
    /// `stiffness`: the linear solve's `K` (unconstrained, N/m); `fixed`: the anchored
    /// DOFs (held at rest).
    pub fn new(
        mesh: &TetMesh,
        gradients: Arc<NodalGradients>,
        elastic: crate::energies::TetElasticity,
        stiffness: SymmetricMatrix,
        fixed: Vec<bool>,
    ) -> Result<Self> {
        let rest = mesh.flat_positions();
        if stiffness.dim() != rest.len() || fixed.len() != rest.len() || gradients.num_nodes() != mesh.num_vertices() {
            return Err(Error::LengthMismatch {
                what: "registration stiffness, anchors and gradients",
                expected: rest.len(),
                got: stiffness.dim().min(fixed.len()),
            });
        }
        let load = crate::energies::ConstantForce::new("registered linear force", vec![0.0; rest.len()])?;
        let terms: [&dyn crate::energy::Energy; 2] = [&elastic, &load];
        let solver = crate::newton::NewtonSolver::new(rest.len(), &terms, fixed)?;
        Ok(Self {
            gradients,
            stiffness,
            elastic,
            solver,
            x: rest.clone(),
            rest,
            relative_tolerance: 1e-6,
        })
    }

    /// Starts a new sequence from the rest shape.
    pub fn reset(&mut self) {
        self.x.copy_from_slice(&self.rest);
    }

    /// `𝓡 K ũ`: the linear internal force, each node's rotated by `exp([w_i]×)`.
    pub fn target_force(&self, linear: &[f64]) -> Result<Vec<f64>> {
        let g = self.gradients.gradients(linear)?;
        let mut f = vec![0.0; linear.len()];
        self.stiffness.mul_vec(linear, &mut f);
        for (i, g) in g.iter().enumerate() {
            let r = Rotation3::from_scaled_axis(rotation_vector(g));
            let fi = r * node(&f, i);
            f[3 * i..3 * i + 3].copy_from_slice(fi.as_slice());
        }
        Ok(f)
    }

    /// Registers the linear displacements `linear` (m, flat) and returns the nonlinear
    /// displacements with the Newton report.
    pub fn register(&mut self, linear: &[f64]) -> Result<(Vec<f64>, crate::newton::NewtonReport)> {
        let target = self.target_force(linear)?;
        let scale = weft_linalg::max_abs(
            target
                .iter()
                .zip(self.solver.fixed())
                .filter(|(_, fixed)| !**fixed)
                .map(|(f, _)| *f),
        );
        let load = crate::energies::ConstantForce::new("registered linear force", target)?;
        let terms: [&dyn crate::energy::Energy; 2] = [&self.elastic, &load];
        let settings = crate::newton::NewtonSettings {
            tolerance: (self.relative_tolerance * scale).max(1e-300),
            max_iterations: 300,
            ..crate::newton::NewtonSettings::default()
        };
        let mut x = self.x.clone();
        let report = self.solver.minimize(&terms, &mut x, &settings)?;
        self.x.copy_from_slice(&x);
        Ok((x.iter().zip(&self.rest).map(|(x, r)| x - r).collect(), report))
    }
}

/// How one NNWarp training sequence is driven (NNWarp §3.2 and §5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SequenceSettings {
    /// Frames over which the load ramps to the one whose static linear answer first
    /// reaches `stop_displacement`.
    pub ramp_frames: usize,
    /// The sequence ends when some node's linear displacement reaches this (m; NNWarp
    /// stops at 2 on the body scaled into the unit sphere) or after `2 · ramp_frames`.
    pub stop_displacement: f64,
    /// Frames appended after the ramp with the load held at its last value, so the damped
    /// linear solve settles to the equilibrium `K ũ = 𝓡ᵀ f` (NNWarp §3.2: "until the
    /// final equilibrium is reached"). The `nnwarp` dataset holds none.
    pub hold_frames: usize,
    /// Young's modulus (Pa) and density (kg/m³); the modulus only scales the load needed
    /// (NNWarp §5: it acts as a linear amplifier).
    pub young: f64,
    pub density: f64,
}

impl Default for SequenceSettings {
    fn default() -> Self {
        Self {
            ramp_frames: 40,
            stop_displacement: 2.0,
            hold_frames: 0,
            young: 1e5,
            density: 1000.0,
        }
    }
}

/// Where one material's registrations leave the branch of equilibria the sequence
/// started on (NNWarp Fig. 2): Newton, warm-started from the previous frame, followed the
/// target onto another branch — a buckled or collapsed shape the warps' rotations do not
/// describe. This frame and every later one of the material are off the branch (each is
/// warm-started from the one before).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffBranch {
    /// The first frame off the branch.
    pub frame: usize,
    /// Tets inverted (`det F ≤ 0`) in its registered shape.
    pub inverted: usize,
    /// Modal warping's `rel-error` against the registered shape at the frame before and
    /// at this one.
    pub warp_error: [f64; 2],
}

/// A rise of modal warping's `rel-error` against the registered shape from one frame to
/// the next beyond both of these (absolute, and as a factor of the previous error) marks
/// a jump to another branch. Along one branch the error grows smoothly with the load: by
/// under 0.03 a frame over the quick ramp's 8 frames, while the co-rotational beam's jump
/// off the branch takes it to 0.23 (issue 70); StVK's genuine material nonlinearity raises
/// it steadily, never doubling it in one frame once it is above 0.05.
const BRANCH_JUMP_RISE: f64 = 0.05;
const BRANCH_JUMP_FACTOR: f64 = 2.0;

/// `rel-error` of `a` against `reference`: the mean node distance over the largest
/// reference displacement (as `weft_nn::nnwarp::rel_error`).
fn warp_rel_error(a: &[f64], reference: &[f64]) -> f64 {
    let n = reference.len() / 3;
    let largest = (0..n).map(|i| node(reference, i).norm()).fold(0.0f64, f64::max);
    if largest == 0.0 {
        return 0.0;
    }
    (0..n).map(|i| (node(a, i) - node(reference, i)).norm()).sum::<f64>() / (n as f64 * largest)
}

/// Tets of `mesh` whose orientation `u` (flat displacements) flips or flattens.
fn inverted_tets(mesh: &TetMesh, u: &[f64]) -> usize {
    use weft_mesh::geometry::tet_signed_volume;
    let rest = mesh.positions();
    let x = |i: usize| rest[i] + node(u, i);
    mesh.tets()
        .iter()
        .filter(|t| {
            let v0 = tet_signed_volume(&rest[t[0]], &rest[t[1]], &rest[t[2]], &rest[t[3]]);
            let v = tet_signed_volume(&x(t[0]), &x(t[1]), &x(t[2]), &x(t[3]));
            v * v0.signum() <= 0.0
        })
        .count()
}

/// Watches one material's registrations frame by frame for [`OffBranch`].
#[derive(Debug, Clone, Default)]
struct BranchWatch {
    previous_error: f64,
    off: Option<OffBranch>,
}

impl BranchWatch {
    fn observe(&mut self, mesh: &TetMesh, frame: usize, modal: &[f64], registered: &[f64]) {
        let error = warp_rel_error(modal, registered);
        if self.off.is_none() {
            let inverted = inverted_tets(mesh, registered);
            let jump =
                error - self.previous_error > BRANCH_JUMP_RISE && error > BRANCH_JUMP_FACTOR * self.previous_error;
            if inverted > 0 || jump {
                self.off = Some(OffBranch {
                    frame,
                    inverted,
                    warp_error: [self.previous_error, error],
                });
            }
        }
        self.previous_error = error;
    }
}

/// A damped quasi-static linear sequence and its registration to each nonlinear material.
#[derive(Debug, Clone, PartialEq)]
pub struct RegisteredSequence {
    /// Field acceleration per frame (m/s²; frame 0 is the rest state, 0).
    pub accelerations: Vec<f64>,
    /// Linear displacements per frame (m, flat), solved in NNWarp's runtime regime
    /// ([`RestFrameSolve`]).
    pub linear: Vec<Vec<f64>>,
    /// Per material (in the order asked), its registered displacements per frame.
    pub nonlinear: Vec<Vec<Vec<f64>>>,
    /// Per material, where its registrations left the sequence's branch, if they did.
    pub off_branch: Vec<Option<OffBranch>>,
    /// The ramp's linear solve (backward Euler, its time step and mass damping), so a
    /// runtime can replay the sequence.
    pub solve: crate::LinearSolve,
    /// Newton iterations over all registrations.
    pub newton_iterations: usize,
    /// Why the sequence stopped before reaching the stop displacement, if it did.
    pub error: Option<String>,
}

/// The unit-acceleration body force of `field` on `mesh` with `masses` (N per m/s²): the
/// training ramp's load per unit of `RegisteredSequence::accelerations`.
pub fn field_forces(rest: &[f64], masses: &[f64], field: FieldDirection) -> Result<Vec<f64>> {
    let f = match field {
        FieldDirection::Directional(d) => crate::energies::ConstantForce::directional(masses, d.into(), 1.0)?,
        FieldDirection::Circular { center, axis } => {
            crate::energies::ConstantForce::circular(masses, rest, center.into(), axis.into(), 1.0)?
        }
    };
    Ok(f.forces().to_vec())
}

/// The ramp's pace from the static deflection `u1` under the unit field `unit`: the
/// acceleration at which the linear answer reaches the stop displacement, and the
/// backward-Euler solve with mass damping `α = 2ω₁` (critical for the first mode, whose
/// `ω₁` is estimated by the Rayleigh quotient of the deflection) and a time step that
/// spans ten first-mode relaxation times (τ₁ = α/ω₁² = 2/ω₁) over the ramp.
fn ramp_pace(
    u1: &[f64],
    unit: &[f64],
    masses: &[f64],
    settings: &SequenceSettings,
) -> Result<(f64, crate::LinearSolve)> {
    let nodes = masses.len();
    let reach = (0..nodes).map(|i| node(u1, i).norm()).fold(0.0f64, f64::max);
    if !(reach > 0.0) {
        return Err(Error::InvalidParameter {
            name: "force field",
            value: reach,
            reason: "moves no node (a field that vanishes on the free nodes)",
        });
    }
    let work: f64 = u1.iter().zip(unit).map(|(u, f)| u * f).sum();
    let inertia: f64 = (0..nodes).map(|i| masses[i] * node(u1, i).norm_squared()).sum();
    let omega = (work / inertia).sqrt();
    let dt = 10.0 * (2.0 / omega) / settings.ramp_frames as f64;
    let damping = crate::integrators::prefactorized::RayleighDamping {
        mass: 2.0 * omega,
        stiffness: 0.0,
    };
    Ok((
        settings.stop_displacement / reach,
        crate::LinearSolve::Dynamic { dt, damping },
    ))
}

/// NNWarp §3.2's training sequence: the body (anchored at `anchors`) under `field`, its
/// magnitude ramped up (then held for `hold_frames`); each frame one damped backward-Euler
/// step of linear elasticity ([`ramp_pace`]), so the linear solution creeps through
/// near-equilibria. Every frame is solved in the runtime's regime ([`RestFrameSolve`]:
/// the load turned into each node's rest frame by the previous frame's rotations, as
/// `NnWarpSimulation` does), then registered (Eq. 6–7) to every material in `materials`,
/// warm-started from the previous frame, and watched for a jump off the branch
/// ([`OffBranch`]).
pub fn register_sequence(
    mesh: &TetMesh,
    anchors: &[usize],
    field: FieldDirection,
    poisson: f64,
    materials: &[crate::energies::Material],
    settings: SequenceSettings,
) -> Result<RegisteredSequence> {
    use crate::energies::{LameParameters, Material, TetElasticity};
    use crate::integrators::prefactorized::{LinearSolve, PrefactorizedLinear};
    if settings.ramp_frames == 0 || !(settings.stop_displacement > 0.0) {
        return Err(Error::InvalidParameter {
            name: "sequence settings",
            value: settings.ramp_frames as f64,
            reason: "need at least one ramp frame and a positive stop displacement",
        });
    }
    let rest = mesh.flat_positions();
    let n = rest.len();
    let lame = LameParameters::from_young_poisson(settings.young, poisson)?;
    let linear_energy = TetElasticity::new(mesh, Material::Linear, lame)?;
    let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), settings.density);
    let fixed = crate::anchors::fixed_dofs(mesh.num_vertices(), anchors)?;
    let unit = field_forces(&rest, &masses, field)?;
    let mut statics = PrefactorizedLinear::new(
        &rest,
        &[&linear_energy],
        masses.clone(),
        fixed.clone(),
        LinearSolve::Static,
    )?;
    statics.step(&unit, &[])?;
    let (a_stop, solve) = ramp_pace(statics.displacements(), &unit, &masses, &settings)?;
    let mut dynamic = RestFrameSolve::new(PrefactorizedLinear::new(
        &rest,
        &[&linear_energy],
        masses,
        fixed.clone(),
        solve,
    )?);
    let gradients = Arc::new(NodalGradients::new(mesh)?);
    let mut registrations = materials
        .iter()
        .map(|&m| {
            Registration::new(
                mesh,
                gradients.clone(),
                TetElasticity::new(mesh, m, lame)?,
                statics.stiffness().clone(),
                fixed.clone(),
            )
        })
        .collect::<Result<Vec<_>>>()?;
    let mut watches = vec![BranchWatch::default(); materials.len()];
    let mut out = RegisteredSequence {
        accelerations: vec![0.0],
        linear: vec![vec![0.0; n]],
        nonlinear: vec![vec![vec![0.0; n]]; materials.len()],
        off_branch: vec![None; materials.len()],
        solve,
        newton_iterations: 0,
        error: None,
    };
    let (mut a, mut held) = (0.0, None::<usize>);
    for k in 1.. {
        match held {
            None if k <= 2 * settings.ramp_frames => a = a_stop * k as f64 / settings.ramp_frames as f64,
            None => held = Some(k),
            Some(_) => {}
        }
        if held.is_some_and(|h| k >= h + settings.hold_frames) {
            break;
        }
        let forces: Vec<f64> = unit.iter().map(|f| f * a).collect();
        let lin = dynamic.step(&forces)?.to_vec();
        dynamic.set_rotations(gradients.rotation_vectors(&lin)?)?;
        let modal = modal_warp(&gradients, &lin)?;
        let mut registered = Vec::with_capacity(materials.len());
        for ((m, reg), watch) in materials.iter().zip(&mut registrations).zip(&mut watches) {
            match reg.register(&lin) {
                Ok((u, report)) => {
                    out.newton_iterations += report.iterations;
                    watch.observe(mesh, k, &modal, &u);
                    registered.push(u);
                }
                Err(e) => {
                    out.error = Some(format!("frame {k}, {}: {e}", m.name()));
                    out.off_branch = watches.iter().map(|w| w.off).collect();
                    return Ok(out);
                }
            }
        }
        let reached = (0..mesh.num_vertices())
            .map(|i| node(&lin, i).norm())
            .fold(0.0f64, f64::max);
        out.accelerations.push(a);
        out.linear.push(lin);
        for (store, u) in out.nonlinear.iter_mut().zip(registered) {
            store.push(u);
        }
        if held.is_none() && reached >= settings.stop_displacement {
            held = Some(k + 1);
        }
    }
    out.off_branch = watches.iter().map(|w| w.off).collect();
    Ok(out)
}
