//! Sparse symmetric linear algebra shared by weft's solvers.
//!
//! Every implicit solve in weft — Newton steps of the simulator, the ACAP Poisson
//! system, the projection layers and their adjoints — assembles a symmetric sparse
//! matrix with a fixed sparsity pattern and factorises it, often many times. This crate
//! is the one place that does so, following faer's symbolic/numeric split: the
//! [`SymmetricPattern`] and its symbolic factorisation are built once per mesh, only the
//! numeric factorisation is repeated.
//!
//! It is deliberately small: upper-triangle CSC storage with O(1) assembly through
//! precomputed slots and a Cholesky solver for SPD matrices ([`CholeskySolver`]). It
//! knows nothing of meshes or physics. (The projection layers' KKT systems are
//! factorised rows-first through this Cholesky, in weft-proj — the only user of them.)
//! Two small pieces of numerics every crate shares sit here because this is the lowest
//! crate they all reach: [`max_abs`], the one max-norm, and [`SplitMix64`], the one seeded
//! pseudo-random generator (weft-sim's scenes and weft-testkit's `TestRng` draw from it).
//! Dense ridge least squares ([`NormalEquations`]) is here for the same reason: it is
//! faer, and the experiments' linear baselines fit it.
//!
//! faer runs single-threaded here: at weft's sizes two threads made faer 2–6× slower on
//! this project's 2-core machines (measured when the dependency was chosen) because its `Par`
//! only splits dense blocks. Large patterns of vertex blocks are instead split by a
//! vertex separator into two domains that faer factorises on one thread each, and whose
//! triangular solves run in parallel ([`Substructuring`]; the `two_domain` module).
//! Otherwise parallelism is over frames and examples.
//!
//! ```
//! use weft_linalg::{CholeskySolver, SymmetricPattern, SymmetricMatrix};
//! use std::sync::Arc;
//! // The 1-D Laplacian plus identity: tridiagonal, SPD.
//! let n = 5;
//! let pattern = Arc::new(SymmetricPattern::new(n, (0..n - 1).map(|i| (i, i + 1))));
//! let mut a = SymmetricMatrix::zeros(pattern.clone());
//! for i in 0..n {
//!     a.add(i, i, 3.0);
//!     if i + 1 < n { a.add(i, i + 1, -1.0); }
//! }
//! let solver = CholeskySolver::new(pattern)?;
//! let factor = solver.factorize(&a)?;
//! let b = vec![1.0; n];
//! let mut x = b.clone();
//! factor.solve_in_place(&mut x);
//! let mut r = vec![0.0; n];
//! a.mul_vec(&x, &mut r);
//! assert!(r.iter().zip(&b).all(|(r, b)| (r - b).abs() < 1e-12));
//! # Ok::<(), weft_linalg::Error>(())
//! ```

mod cholesky;
mod error;
mod krylov;
mod norms;
mod ordering;
mod pattern;
mod ridge;
mod rng;
mod two_domain;

pub use cholesky::{CholeskyFactor, CholeskySolver, Substructuring};
pub use error::{Error, Result};
pub use krylov::{CgOutcome, pcg};
pub use norms::{dot, max_abs, rank_correlation};
pub use pattern::{SymmetricMatrix, SymmetricPattern};
pub use ridge::NormalEquations;
pub use rng::SplitMix64;

#[cfg(test)]
mod tests;
