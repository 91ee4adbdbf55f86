//! The energy abstraction every solver in weft minimises.
//!
//! Implicit Euler, quasistatic equilibrium and the projection layers all solve
//! `min_x Σ_k E_k(x)` over a flat DOF vector `x = [x0, y0, z0, x1, …]` (metres). Each term
//! gives its value (J), gradient (N) and Hessian (N/m), the Hessian optionally projected
//! to positive semi-definite *per element* so that Newton's direction is always a
//! descent direction (Teran et al. 2005; Tan et al. Eq. 4 is solved this way).

use nalgebra::allocator::Allocator;
use nalgebra::{Const, DefaultAllocator, DimDiff, DimSub, SMatrix, SVector, U1};
use weft_linalg::SymmetricMatrix;

/// A term of a total potential over flat positions `x` (3 DOFs per vertex).
pub trait Energy: Send + Sync + std::fmt::Debug {
    /// Short name for reports (`"stretch springs"`, `"inertia"`, …).
    fn name(&self) -> &'static str;
    /// Appends every vertex pair whose DOFs this term couples (the Hessian's pattern).
    fn hessian_pairs(&self, pairs: &mut Vec<(usize, usize)>);
    /// Energy (J).
    fn value(&self, x: &[f64]) -> f64;
    /// Adds `∂E/∂x` into `grad`.
    fn add_gradient(&self, x: &[f64], grad: &mut [f64]);
    /// Adds `∂²E/∂x²` into `hessian` (whose pattern includes [`Energy::hessian_pairs`]);
    /// with `project`, each element's block is first made positive semi-definite.
    fn add_hessian(&self, x: &[f64], project: bool, hessian: &mut SymmetricMatrix);
    /// The DOF count a term with per-DOF or per-vertex data (forces, masses, targets,
    /// contact over all vertices) was built for; `None` for terms over mesh elements,
    /// whose vertex indices [`Energy::hessian_pairs`] exposes. Solvers check both against
    /// their DOF count up front, so a mismatched term is an error, not a panic or a load
    /// silently truncated.
    fn num_dofs(&self) -> Option<usize> {
        None
    }
    /// `E(to) − E(from)`. An affine term (gravity, a constant load) overrides it with the
    /// exact `−f·(to − from)`: its value `−f·x` grows with the distance from the origin,
    /// and the difference of two such values would lose the change to cancellation.
    fn value_change(&self, from: &[f64], to: &[f64]) -> f64 {
        self.value(to) - self.value(from)
    }
    /// Whether the term is affine in `x`, so its [`Energy::value_change`] is exact and its
    /// value carries no round-off that the line search must respect.
    fn is_affine(&self) -> bool {
        false
    }
}

/// Checks every term against `num_dofs` (see [`Energy::num_dofs`]) and returns the vertex
/// pairs of their Hessians.
pub fn checked_pairs(num_dofs: usize, terms: &[&dyn Energy]) -> crate::Result<Vec<(usize, usize)>> {
    let mut pairs = Vec::new();
    for t in terms {
        if let Some(n) = t.num_dofs() {
            if n != num_dofs {
                return Err(crate::Error::LengthMismatch {
                    what: t.name(),
                    expected: num_dofs,
                    got: n,
                });
            }
        }
        t.hessian_pairs(&mut pairs);
    }
    let nv = num_dofs / 3;
    if let Some(&(a, b)) = pairs.iter().find(|&&(a, b)| a >= nv || b >= nv) {
        return Err(crate::Error::VertexOutOfRange {
            what: "energy term",
            index: a.max(b),
            num_vertices: nv,
        });
    }
    Ok(pairs)
}

/// The terms of a step's objective: a scene's potential `terms` followed by the
/// integrator's own (inertia, damping) — as the trait objects the solvers take.
pub fn with_extra<'a>(terms: &'a [Box<dyn Energy>], extra: &[&'a dyn Energy]) -> Vec<&'a dyn Energy> {
    terms.iter().map(|t| t.as_ref()).chain(extra.iter().copied()).collect()
}

/// Sum of the values of several terms.
pub fn total_value(terms: &[&dyn Energy], x: &[f64]) -> f64 {
    terms.iter().map(|t| t.value(x)).sum()
}

/// Sum of the gradients of several terms (overwrites `grad`).
pub fn total_gradient(terms: &[&dyn Energy], x: &[f64], grad: &mut [f64]) {
    grad.iter_mut().for_each(|g| *g = 0.0);
    for t in terms {
        t.add_gradient(x, grad);
    }
}

/// The diagonal of `Σ_k ∂²E_k/∂x²` at `x` (N/m), each element block projected to
/// positive semi-definite with `project`. Assembled through the terms' own Hessians, so
/// it is the diagonal Newton factorises, not a second formula for it.
pub fn total_hessian_diagonal(
    num_dofs: usize,
    terms: &[&dyn Energy],
    x: &[f64],
    project: bool,
) -> crate::Result<Vec<f64>> {
    if x.len() != num_dofs {
        return Err(crate::Error::LengthMismatch {
            what: "positions",
            expected: num_dofs,
            got: x.len(),
        });
    }
    let pairs = checked_pairs(num_dofs, terms)?;
    let pattern = std::sync::Arc::new(weft_linalg::SymmetricPattern::from_vertex_pairs(num_dofs / 3, pairs));
    let mut hessian = SymmetricMatrix::zeros(pattern);
    for t in terms {
        t.add_hessian(x, project, &mut hessian);
    }
    Ok((0..num_dofs).map(|i| hessian.get(i, i)).collect())
}

/// Position of vertex `v` in a flat DOF vector.
#[inline]
pub fn vertex(x: &[f64], v: usize) -> nalgebra::Vector3<f64> {
    nalgebra::Vector3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2])
}

/// Adds a local gradient over `verts` (3 entries per vertex) into a global one.
#[inline]
pub fn scatter_gradient<const D: usize>(verts: &[usize], local: &SVector<f64, D>, grad: &mut [f64]) {
    for (a, &v) in verts.iter().enumerate() {
        for k in 0..3 {
            grad[3 * v + k] += local[3 * a + k];
        }
    }
}

/// Adds a local `D × D` Hessian over `verts` into the global matrix (upper triangle).
#[inline]
pub fn scatter_hessian<const D: usize>(verts: &[usize], local: &SMatrix<f64, D, D>, hessian: &mut SymmetricMatrix) {
    for (a, &va) in verts.iter().enumerate() {
        for (b, &vb) in verts.iter().enumerate() {
            if va <= vb {
                let block = [0, 1, 2].map(|i| [0, 1, 2].map(|j| local[(3 * a + i, 3 * b + j)]));
                hessian.add_vertex_block(va, vb, &block);
            }
        }
    }
}

/// Projects a symmetric matrix onto the positive semi-definite cone by clamping its
/// negative eigenvalues to zero (Teran, Sifakis, Irving, Fedkiw 2005, §4).
///
/// Fixed-size, so the one implementation serves every element block (`9 × 9` membrane
/// and `∂P/∂F`, `12 × 12` hinge) without a heap matrix per call.
pub fn project_psd<const D: usize>(m: &SMatrix<f64, D, D>) -> SMatrix<f64, D, D>
where
    Const<D>: DimSub<U1>,
    DefaultAllocator: Allocator<DimDiff<Const<D>, U1>>,
{
    let sym = 0.5 * (m + m.transpose());
    // Fast path: most element blocks are already PSD; a Cholesky of a tiny positive
    // shift (rigid modes make the blocks singular) proves it far cheaper than an
    // eigen-decomposition.
    let scale = (0..D)
        .map(|i| sym[(i, i)].abs())
        .fold(0.0, f64::max)
        .max(f64::MIN_POSITIVE);
    let mut shifted = sym;
    for i in 0..D {
        shifted[(i, i)] += 1e-12 * scale;
    }
    if shifted.cholesky().is_some() {
        return *m;
    }
    let eig = sym.symmetric_eigen();
    if eig.eigenvalues.iter().all(|&l| l >= 0.0) {
        return *m;
    }
    let clamped = eig.eigenvalues.map(|l| l.max(0.0));
    eig.eigenvectors * SMatrix::<f64, D, D>::from_diagonal(&clamped) * eig.eigenvectors.transpose()
}

/// All vertex pairs of an element (for [`Energy::hessian_pairs`]).
pub fn element_pairs(verts: &[usize], pairs: &mut Vec<(usize, usize)>) {
    for (a, &u) in verts.iter().enumerate() {
        for &v in &verts[a + 1..] {
            pairs.push((u, v));
        }
    }
}
