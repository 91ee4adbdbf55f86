//! The sparse linear algebra of the inextensibility layer: matrices
//! `K + Σ_e D_eᵀ G_e D_e` (`D_e = E_a − E_b`, `G_e` a symmetric `3 × 3` block per mesh
//! edge) over the mesh-edge vertex pattern, and the edge KKT systems of the polish and
//! the backward pass, factorised through them.
//!
//! Every linear solve of the layer — each interior-point iteration, each polish Newton
//! step, the backward pass — reduces to one matrix of that form, so one
//! [`CholeskySolver`] (ordering and symbolic analysis once per mesh) serves
//! them all.
//!
//! # The KKT systems as a rows-first block LDLᵀ
//!
//! The polish and the backward pass solve
//!
//! ```text
//! 𝒦 = ⎡ K + Σ_e D_eᵀ B_e D_e    D_eᵀ c_e ⎤
//!     ⎣ c_eᵀ D_e                σ_e      ⎦      (one row per edge, σ_e ≤ 0)
//! ```
//!
//! whose constraint block is diagonal: rows couple only to the two vertices of their
//! edge. Ordering every row before the primal unknowns, the LDLᵀ factorisation of `𝒦` is
//! `1 × 1` pivots `p_e` for the rows followed by the factorisation of their Schur
//! complement `S = K + Σ_e D_eᵀ (B_e − c_e c_eᵀ / p_e) D_e` — a matrix of the form above,
//! positive definite for `p_e < 0`, factorised by the shared Cholesky. This order adds
//! no fill: eliminating a row couples only `a` and `b`, already coupled by the mesh edge.
//! (A scalar AMD on `𝒦` nearly chooses this order itself — rows have the smallest
//! degree — but orders scalars rather than vertex blocks and pays per-row supernode
//! overhead.)
//!
//! A row of an active edge has `σ_e = 0` (polish) or `σ_e ≈ 0` (backward), so its pivot
//! is regularised, sign-aware, to `p_e = min(σ_e, −δ)`; iterative refinement against the
//! unregularised `𝒦` then removes the regularisation's bias, exactly as for a
//! dynamically regularised sparse LDLᵀ. For dependent
//! constraint rows (Geng et al. Appendix A) the regularisation picks one multiplier
//! solution and refinement converges on the consistent part.

use std::sync::Arc;

use nalgebra::{Matrix3, Vector3};
use weft_linalg::{CholeskyFactor, CholeskySolver, SymmetricMatrix, SymmetricPattern};

use crate::error::Result;

/// A symmetric `3 × 3` block, row-major, as [`SymmetricMatrix::add_vertex_block`] takes it.
pub(crate) type Block3 = [[f64; 3]; 3];

/// `K + Σ_e D_eᵀ G_e D_e` over some of a mesh's edges: those edges, their indices in
/// the mesh's edge list, the vertex weights `w_v` (`K = diag(w_v) ⊗ I₃`) and the symbolic
/// Cholesky factor of its pattern.
#[derive(Debug)]
pub(crate) struct EdgeSystem {
    edges: Vec<[usize; 2]>,
    ids: Vec<usize>,
    weights: Vec<f64>,
    cholesky: CholeskySolver,
    /// Storage slots of the diagonal entries of each vertex block.
    diagonal_slots: Vec<[u32; 3]>,
    /// Per edge `(a, b)`: the slots of the upper triangles of the vertex blocks `(a, a)`
    /// and `(b, b)` (in [`UPPER`] order), then of the nine entries of the coupling
    /// block (row-major from the smaller vertex). Assembly is then a scatter, with no
    /// search per block (the IPM assembles the full system every iteration).
    edge_slots: Vec<[u32; 21]>,
}

/// The upper-triangle entries `(i, j)`, `i ≤ j`, of a `3 × 3` block.
const UPPER: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

impl EdgeSystem {
    /// The system over every edge of the mesh.
    pub fn new(num_vertices: usize, edges: &[[usize; 2]], weights: &[f64]) -> Result<Self> {
        debug_assert_eq!(weights.len(), num_vertices);
        Self::over(edges.to_vec(), (0..edges.len()).collect(), weights.to_vec())
    }

    fn over(edges: Vec<[usize; 2]>, ids: Vec<usize>, weights: Vec<f64>) -> Result<Self> {
        let pattern = SymmetricPattern::from_vertex_pairs(weights.len(), edges.iter().map(|&[a, b]| (a, b)));
        let slot = |r: usize, c: usize| {
            let slot = pattern.slot(r, c).expect("a vertex block of its own pattern");
            u32::try_from(slot).expect("fewer than 2³² stored entries")
        };
        let diagonal_slots = (0..weights.len())
            .map(|v| std::array::from_fn(|c| slot(3 * v + c, 3 * v + c)))
            .collect();
        let edge_slots = edges
            .iter()
            .map(|&[a, b]| {
                let (u, v) = (a.min(b), a.max(b));
                std::array::from_fn(|k| match k {
                    0..6 => slot(3 * a + UPPER[k].0, 3 * a + UPPER[k].1),
                    6..12 => slot(3 * b + UPPER[k - 6].0, 3 * b + UPPER[k - 6].1),
                    _ => slot(3 * u + (k - 12) / 3, 3 * v + (k - 12) % 3),
                })
            })
            .collect();
        let cholesky = CholeskySolver::new(Arc::new(pattern))?;
        Ok(Self {
            edges,
            ids,
            weights,
            cholesky,
            diagonal_slots,
            edge_slots,
        })
    }

    /// The system over the edges with `keep[id]` only (its own symbolic analysis): after
    /// the polish every other edge is exactly decoupled, and the Cholesky factor of the
    /// active edges' pattern is an order of magnitude cheaper than the full one.
    pub fn restricted(&self, keep: &[bool]) -> Result<Self> {
        let (ids, edges) = self
            .ids
            .iter()
            .zip(&self.edges)
            .filter(|&(&id, _)| keep[id])
            .map(|(&id, &edge)| (id, edge))
            .unzip();
        Self::over(edges, ids, self.weights.clone())
    }

    pub fn edges(&self) -> &[[usize; 2]] {
        &self.edges
    }

    /// The index in the mesh's edge list of each of [`Self::edges`].
    pub fn ids(&self) -> &[usize] {
        &self.ids
    }

    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Assembles `K + Σ_e D_eᵀ G_e D_e`.
    fn assemble(&self, blocks: &[Block3]) -> SymmetricMatrix {
        let mut matrix = SymmetricMatrix::zeros(self.cholesky.pattern().clone());
        let values = matrix.values_mut();
        for (slots, &w) in self.diagonal_slots.iter().zip(&self.weights) {
            slots.iter().for_each(|&s| values[s as usize] += w);
        }
        for (slots, g) in self.edge_slots.iter().zip(blocks) {
            for (k, &(i, j)) in UPPER.iter().enumerate() {
                values[slots[k] as usize] += g[i][j];
                values[slots[6 + k] as usize] += g[i][j];
            }
            // G is symmetric, so the coupling block is −G either way round.
            for k in 0..9 {
                values[slots[12 + k] as usize] -= g[k / 3][k % 3];
            }
        }
        matrix
    }

    /// The Cholesky factor of `K + Σ_e D_eᵀ G_e D_e`.
    pub fn factorize(&self, blocks: &[Block3]) -> Result<CholeskyFactor> {
        Ok(self.cholesky.factorize(&self.assemble(blocks))?)
    }

    /// `y += (K + Σ_e D_eᵀ G_e D_e) x`, edge by edge (no assembled matrix needed).
    pub fn add_product(&self, blocks: &[Block3], x: &[f64], y: &mut [f64]) {
        for (i, yi) in y.iter_mut().enumerate() {
            *yi += self.weights[i / 3] * x[i];
        }
        for (&[a, b], g) in self.edges.iter().zip(blocks) {
            let gd = mul3(g, &self.edge_difference(a, b, x));
            for c in 0..3 {
                y[3 * a + c] += gd[c];
                y[3 * b + c] -= gd[c];
            }
        }
    }

    /// `D_e x = x_a − x_b`.
    #[inline]
    pub fn edge_difference(&self, a: usize, b: usize, x: &[f64]) -> [f64; 3] {
        [
            x[3 * a] - x[3 * b],
            x[3 * a + 1] - x[3 * b + 1],
            x[3 * a + 2] - x[3 * b + 2],
        ]
    }

    /// Factorises the edge KKT matrix `𝒦` with one row per edge of this system (`blocks`
    /// in the order of [`Self::edges`]; see the module doc): row pivots `min(σ_e, −δ)`,
    /// then the Cholesky factor of their Schur complement.
    pub fn factorize_kkt(&self, blocks: Vec<EdgeBlock>, delta: f64, refinement_steps: usize) -> Result<KktFactor<'_>> {
        let pivots: Vec<f64> = blocks.iter().map(|blk| blk.diagonal.min(-delta)).collect();
        let schur: Vec<Block3> = blocks
            .iter()
            .zip(&pivots)
            .map(|(blk, &p)| {
                let mut g = blk.primal;
                if let Some(c) = blk.coupling {
                    g -= c * c.transpose() / p;
                }
                std::array::from_fn(|i| std::array::from_fn(|j| g[(i, j)]))
            })
            .collect();
        let factor = self.factorize(&schur)?;
        Ok(KktFactor {
            system: self,
            blocks,
            pivots,
            factor,
            refinement_steps,
        })
    }
}

/// One edge's part of an edge KKT matrix: `D_eᵀ B D_e` in the primal block, `D_eᵀ c`
/// coupling to the edge's row, `σ` on the row's diagonal.
#[derive(Debug, Clone, Copy)]
pub(crate) struct EdgeBlock {
    pub primal: Matrix3<f64>,
    pub coupling: Option<Vector3<f64>>,
    pub diagonal: f64,
}

impl EdgeBlock {
    /// An edge without a constraint row: its multiplier decouples (`−1 · ν = 0`).
    pub fn decoupled() -> Self {
        Self {
            primal: Matrix3::zeros(),
            coupling: None,
            diagonal: -1.0,
        }
    }
}

/// The regularised rows-first LDLᵀ of an edge KKT matrix, kept with its blocks for
/// iterative refinement. Unknowns are laid out `[primal (3V); one multiplier per edge of
/// the system]`.
#[derive(Debug)]
pub(crate) struct KktFactor<'a> {
    system: &'a EdgeSystem,
    blocks: Vec<EdgeBlock>,
    pivots: Vec<f64>,
    factor: CholeskyFactor,
    refinement_steps: usize,
}

impl KktFactor<'_> {
    /// Solves with the regularised factor: `S x = f − Σ_e D_eᵀ c_e g_e / p_e`, then
    /// `ν_e = (g_e − c_eᵀ D_e x) / p_e`.
    fn solve_regularised(&self, rhs: &mut [f64]) {
        let n = self.factor.dim();
        let (x, nu) = rhs.split_at_mut(n);
        for ((&[a, b], blk), (&g, &p)) in self
            .system
            .edges
            .iter()
            .zip(&self.blocks)
            .zip(nu.iter().zip(&self.pivots))
        {
            if let Some(c) = blk.coupling {
                for k in 0..3 {
                    x[3 * a + k] -= c[k] * g / p;
                    x[3 * b + k] += c[k] * g / p;
                }
            }
        }
        self.factor.solve_in_place(x);
        for ((&[a, b], blk), (nu, &p)) in self
            .system
            .edges
            .iter()
            .zip(&self.blocks)
            .zip(nu.iter_mut().zip(&self.pivots))
        {
            let cd = blk.coupling.map_or(0.0, |c| {
                let d = self.system.edge_difference(a, b, x);
                c[0] * d[0] + c[1] * d[1] + c[2] * d[2]
            });
            *nu = (*nu - cd) / p;
        }
    }

    /// `b − 𝒦 [x; ν]` with the unregularised `𝒦`.
    fn residual(&self, solution: &[f64], b: &[f64]) -> Vec<f64> {
        let n = self.factor.dim();
        let (x, nu) = solution.split_at(n);
        let mut r = b.to_vec();
        let (rx, rnu) = r.split_at_mut(n);
        for (i, ri) in rx.iter_mut().enumerate() {
            *ri -= self.system.weights[i / 3] * x[i];
        }
        for (e, (&[a, b], blk)) in self.system.edges.iter().zip(&self.blocks).enumerate() {
            let d = Vector3::from(self.system.edge_difference(a, b, x));
            let mut force = blk.primal * d;
            rnu[e] -= blk.diagonal * nu[e];
            if let Some(c) = blk.coupling {
                force += c * nu[e];
                rnu[e] -= c.dot(&d);
            }
            for k in 0..3 {
                rx[3 * a + k] -= force[k];
                rx[3 * b + k] += force[k];
            }
        }
        r
    }

    /// Solves `𝒦 [x; ν] = rhs` in place, refining against the unregularised `𝒦`;
    /// returns the final relative residual `‖b − 𝒦 x‖ / ‖b‖`.
    pub fn solve_in_place(&self, rhs: &mut [f64]) -> f64 {
        let b = rhs.to_vec();
        let b_norm = norm(&b).max(f64::MIN_POSITIVE);
        self.solve_regularised(rhs);
        let mut relative = 0.0;
        for step in 0..=self.refinement_steps {
            let mut r = self.residual(rhs, &b);
            relative = norm(&r) / b_norm;
            if step == self.refinement_steps || relative < 1e-15 {
                break;
            }
            self.solve_regularised(&mut r);
            rhs.iter_mut().zip(&r).for_each(|(x, d)| *x += d);
        }
        relative
    }
}

fn mul3(g: &Block3, d: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| g[i][0] * d[0] + g[i][1] * d[1] + g[i][2] * d[2])
}

fn norm(x: &[f64]) -> f64 {
    x.iter().map(|v| v * v).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// Two triangles sharing an edge, plus a dangling edge: 5 vertices, 6 edges.
    const EDGES: [[usize; 2]; 6] = [[0, 1], [1, 2], [2, 0], [1, 3], [3, 2], [3, 4]];
    const WEIGHTS: [f64; 5] = [0.7, 1.3, 1.0, 0.9, 1.1];

    /// The dense KKT matrix over `[3V; one row per edge of system]`.
    fn dense_kkt(system: &EdgeSystem, blocks: &[EdgeBlock]) -> DMatrix<f64> {
        let n = 3 * WEIGHTS.len();
        let k = system.edges().len();
        let mut a = DMatrix::zeros(n + k, n + k);
        for i in 0..n {
            a[(i, i)] = WEIGHTS[i / 3];
        }
        for (row, (&[u, v], blk)) in system.edges().iter().zip(blocks).enumerate() {
            for i in 0..3 {
                for j in 0..3 {
                    let h = blk.primal[(i, j)];
                    a[(3 * u + i, 3 * u + j)] += h;
                    a[(3 * v + i, 3 * v + j)] += h;
                    a[(3 * u + i, 3 * v + j)] -= h;
                    a[(3 * v + i, 3 * u + j)] -= h;
                }
                if let Some(c) = blk.coupling {
                    for (r, sign) in [(3 * u + i, 1.0), (3 * v + i, -1.0)] {
                        a[(r, n + row)] = sign * c[i];
                        a[(n + row, r)] = sign * c[i];
                    }
                }
            }
            a[(n + row, n + row)] = blk.diagonal;
        }
        a
    }

    fn unit(x: f64, y: f64, z: f64) -> Vector3<f64> {
        Vector3::new(x, y, z).normalize()
    }

    /// Active rows (σ = 0, the polish's case), a row with a small negative diagonal and
    /// an eliminated one (the backward's cases) and a decoupled one.
    fn mixed_blocks() -> Vec<EdgeBlock> {
        let curvature = |u: Vector3<f64>, s: f64| (Matrix3::identity() - u * u.transpose()) * s;
        vec![
            EdgeBlock {
                primal: curvature(unit(1.0, 0.2, 0.0), 0.3),
                coupling: Some(unit(1.0, 0.2, 0.0)),
                diagonal: 0.0,
            },
            EdgeBlock {
                primal: curvature(unit(-0.3, 1.0, 0.1), 0.7),
                coupling: Some(unit(-0.3, 1.0, 0.1)),
                diagonal: 0.0,
            },
            EdgeBlock {
                primal: Matrix3::identity() * 0.2,
                coupling: Some(unit(0.5, -1.0, 0.2) * 0.9),
                diagonal: -1e-3,
            },
            EdgeBlock {
                primal: Matrix3::identity() * 0.05 + unit(0.0, 1.0, 1.0) * unit(0.0, 1.0, 1.0).transpose(),
                ..EdgeBlock::decoupled()
            },
            EdgeBlock::decoupled(),
            EdgeBlock {
                primal: Matrix3::zeros(),
                coupling: Some(unit(0.1, 0.1, 1.0)),
                diagonal: 0.0,
            },
        ]
    }

    fn rhs(len: usize) -> Vec<f64> {
        (0..len).map(|i| (0.37 * i as f64 + 0.2).sin()).collect()
    }

    #[test]
    fn rows_first_ldlt_solves_the_kkt_system() {
        let system = EdgeSystem::new(5, &EDGES, &WEIGHTS).unwrap();
        let blocks = mixed_blocks();
        let dense = dense_kkt(&system, &blocks);
        let b = rhs(15 + 6);
        let expected = dense.clone().lu().solve(&DVector::from_vec(b.clone())).unwrap();
        let factor = system.factorize_kkt(blocks, 1e-9, 3).unwrap();
        let mut x = b.clone();
        let residual = factor.solve_in_place(&mut x);
        assert!(residual < 1e-14, "relative residual {residual:e}");
        let err = (DVector::from_vec(x) - &expected).amax() / expected.amax();
        assert!(err < 1e-12, "vs dense LU: {err:e}");
    }

    #[test]
    fn restricted_system_matches_the_full_one_on_decoupled_edges() {
        let full = EdgeSystem::new(5, &EDGES, &WEIGHTS).unwrap();
        let mut blocks = mixed_blocks();
        blocks[3] = EdgeBlock::decoupled();
        let keep: Vec<bool> = blocks.iter().map(|blk| blk.coupling.is_some()).collect();
        let restricted = full.restricted(&keep).unwrap();
        assert_eq!(restricted.ids(), &[0, 1, 2, 5]);
        let b = rhs(15 + 6);
        let mut x_full = b.clone();
        full.factorize_kkt(blocks.clone(), 1e-9, 3)
            .unwrap()
            .solve_in_place(&mut x_full);
        // The restricted layout has rows for its edges only; a decoupled row's
        // multiplier is −b (its equation is −ν = b).
        let mut x = b[..15].to_vec();
        x.extend(restricted.ids().iter().map(|&e| b[15 + e]));
        let kept: Vec<EdgeBlock> = restricted.ids().iter().map(|&e| blocks[e]).collect();
        restricted.factorize_kkt(kept, 1e-9, 3).unwrap().solve_in_place(&mut x);
        for i in 0..15 {
            assert!(
                (x[i] - x_full[i]).abs() < 1e-12,
                "primal {i}: {} vs {}",
                x[i],
                x_full[i]
            );
        }
        for (k, &e) in restricted.ids().iter().enumerate() {
            assert!((x[15 + k] - x_full[15 + e]).abs() < 1e-12);
        }
    }

    /// Geng et al. Appendix A: three collinear active edges of a triangle have dependent
    /// constraint rows, so the KKT matrix is singular. For a consistent right-hand side
    /// the regularised factor plus refinement still solves it, and the primal part — the
    /// one the backward pass uses — is unique.
    #[test]
    fn dependent_rows_are_solved_for_a_consistent_right_hand_side() {
        let system = EdgeSystem::new(5, &EDGES, &WEIGHTS).unwrap();
        let along = Vector3::x();
        let active = EdgeBlock {
            primal: Matrix3::zeros(),
            coupling: Some(along),
            diagonal: 0.0,
        };
        // Edges (0,1), (1,2), (2,0) all along x: c₀₁ᵀ(r₀−r₁) + c₁₂ᵀ(r₁−r₂) + c₂₀ᵀ(r₂−r₀) ≡ 0.
        let blocks = vec![
            active,
            active,
            active,
            EdgeBlock::decoupled(),
            EdgeBlock::decoupled(),
            EdgeBlock::decoupled(),
        ];
        let dense = dense_kkt(&system, &blocks);
        let mut b = rhs(15 + 6);
        b[15..18].iter_mut().for_each(|v| *v = 0.0);
        let factor = system.factorize_kkt(blocks, 1e-9, 3).unwrap();
        let mut x = b.clone();
        let residual = factor.solve_in_place(&mut x);
        assert!(residual < 1e-12, "relative residual {residual:e}");
        let r = &dense * DVector::from_vec(x.clone()) - DVector::from_vec(b.clone());
        assert!(r.amax() < 1e-12);
        // Any other solution differs by a null vector, which has no primal part.
        let shifted: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, v)| if (15..18).contains(&i) { v + 1.0 } else { *v })
            .collect();
        let r_shifted = &dense * DVector::from_vec(shifted) - DVector::from_vec(b);
        assert!(
            r_shifted.amax() < 1e-12,
            "(1, 1, 1) on the three rows is the null space"
        );
    }
}
