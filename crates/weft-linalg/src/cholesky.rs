//! Sparse Cholesky on faer, symbolic analysis once per pattern and numeric factorisation
//! per call, with the vertex-graph ordering choice and the two-domain split.

use std::sync::Arc;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{LltParams, LltRegularization};
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::{Conj, MatMut, Par, Side, Spec};

use crate::ordering;
use crate::two_domain::{self, Domain, FactorValues, TwoDomain, TwoDomainFactor};
use crate::{Error, Result, SymmetricMatrix, SymmetricPattern};

fn single_threaded() {
    faer::set_global_parallelism(Par::Seq);
}

/// Whether [`CholeskySolver`] splits the matrix into two domains factorised and solved
/// on two threads (see the `two_domain` module: vertex-separator substructuring).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Substructuring {
    /// Split when the pattern has vertex blocks, at least `MIN_SPLIT_VERTICES`
    /// vertices, rayon has two or more threads, a level-set separator of at most 10 %
    /// of the vertices exists, and the larger domain's factor is at most three times
    /// the smaller's.
    #[default]
    Auto,
    /// One sequential factorisation.
    Never,
    /// Split whenever a balanced separator exists (for tests of the split path).
    Always,
}

/// Smallest vertex count at which [`Substructuring::Auto`] considers splitting: below
/// it, the threads' start-up costs more than half a factorisation.
pub const MIN_SPLIT_VERTICES: usize = 2000;

/// Sparse Cholesky `A = L Lᵀ` with the symbolic analysis (fill-reducing ordering,
/// elimination tree, supernodes) done once per pattern.
///
/// Patterns of `3 × 3` vertex blocks are ordered on the vertex graph by the better of
/// AMD and a level-set (banded) order, and large ones are split into two domains that
/// are factorised and solved in parallel ([`Substructuring`]); other patterns use AMD on
/// the scalar graph.
#[derive(Debug, Clone)]
pub struct CholeskySolver {
    pattern: Arc<SymmetricPattern>,
    kind: SolverKind,
}

#[derive(Debug, Clone)]
enum SolverKind {
    /// A scalar pattern, AMD-ordered by faer.
    Scalar(Arc<SymbolicCholesky<usize>>),
    /// A vertex-block pattern as one domain in its chosen vertex order.
    Single(Arc<Domain>),
    TwoDomain(Arc<TwoDomain>),
}

/// A numeric Cholesky factor, ready for solves.
#[derive(Debug, Clone)]
pub struct CholeskyFactor {
    n: usize,
    kind: FactorKind,
}

#[derive(Debug, Clone)]
enum FactorKind {
    Scalar {
        symbolic: Arc<SymbolicCholesky<usize>>,
        values: Vec<f64>,
    },
    Single {
        domain: Arc<Domain>,
        values: FactorValues,
    },
    TwoDomain(TwoDomainFactor),
}

fn symbolic_with(
    pattern: &SymmetricPattern,
    ordering: SymmetricOrdering<'_, usize>,
) -> Result<SymbolicCholesky<usize>> {
    factorize_symbolic_cholesky(
        pattern.symbolic.as_ref(),
        Side::Upper,
        ordering,
        CholeskySymbolicParams::default(),
    )
    .map_err(|e| Error::Setup(format!("{e:?}")))
}

impl CholeskySolver {
    pub fn new(pattern: Arc<SymmetricPattern>) -> Result<Self> {
        Self::with_substructuring(pattern, Substructuring::Auto)
    }

    pub fn with_substructuring(pattern: Arc<SymmetricPattern>, substructuring: Substructuring) -> Result<Self> {
        single_threaded();
        let Some(graph) = pattern.vertex_graph() else {
            let symbolic = symbolic_with(&pattern, SymmetricOrdering::Amd)?;
            return Ok(Self {
                pattern,
                kind: SolverKind::Scalar(Arc::new(symbolic)),
            });
        };
        let split = match substructuring {
            Substructuring::Never => None,
            Substructuring::Always => ordering::level_bisection(&graph, 0.5),
            Substructuring::Auto => (graph.len() >= MIN_SPLIT_VERTICES && rayon::current_num_threads() >= 2)
                .then(|| ordering::level_bisection(&graph, 0.1))
                .flatten(),
        };
        if let Some(b) = split {
            let (interiors, lens) = two_domain::plan(&graph, &b)?;
            // Balanced domains (the larger at most 3× the smaller) run the two threads
            // about equally long; otherwise one thread does most of the work anyway.
            let worth_it = substructuring == Substructuring::Always || lens[0].max(lens[1]) <= 3 * lens[0].min(lens[1]);
            if worth_it {
                let two = TwoDomain::new(&pattern, &graph, interiors, &b.separator)?;
                return Ok(Self {
                    pattern,
                    kind: SolverKind::TwoDomain(Arc::new(two)),
                });
            }
        }
        let (order, _) = graph.best_order()?;
        let kind = SolverKind::Single(Arc::new(Domain::new(&pattern, &graph, &order, &[])?));
        Ok(Self { pattern, kind })
    }

    pub fn pattern(&self) -> &Arc<SymmetricPattern> {
        &self.pattern
    }

    /// Number of stored entries of the factor (a measure of fill; for a split factor,
    /// both domains plus the dense separator block).
    pub fn factor_nnz(&self) -> usize {
        match &self.kind {
            SolverKind::Scalar(s) => s.len_val(),
            SolverKind::Single(d) => d.factor_len(),
            SolverKind::TwoDomain(t) => t.factor_len(),
        }
    }

    /// Number of domains the factorisation is split into (1 or 2).
    pub fn domains(&self) -> usize {
        match self.kind {
            SolverKind::Scalar(_) | SolverKind::Single(_) => 1,
            SolverKind::TwoDomain(_) => 2,
        }
    }

    /// The numeric factorisation of `a`, whose pattern must be this solver's.
    pub fn factorize(&self, a: &SymmetricMatrix) -> Result<CholeskyFactor> {
        assert!(
            Arc::ptr_eq(&self.pattern, &a.pattern) || self.pattern.nnz() == a.pattern.nnz(),
            "pattern mismatch"
        );
        a.check_finite()?;
        let kind = match &self.kind {
            SolverKind::Single(domain) => FactorKind::Single {
                domain: domain.clone(),
                values: domain.factorize_numeric(a)?,
            },
            SolverKind::Scalar(symbolic) => {
                let mut values = vec![0.0; symbolic.len_val()];
                let par = Par::Seq;
                let params: Spec<LltParams, f64> = Default::default();
                let mut mem = MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(par, params));
                symbolic
                    .factorize_numeric_llt::<f64>(
                        &mut values,
                        a.as_faer(),
                        Side::Upper,
                        LltRegularization::default(),
                        par,
                        MemStack::new(&mut mem),
                        params,
                    )
                    .map_err(|_| Error::NotPositiveDefinite)?;
                FactorKind::Scalar {
                    symbolic: symbolic.clone(),
                    values,
                }
            }
            SolverKind::TwoDomain(two) => FactorKind::TwoDomain(two.factorize(a)?),
        };
        Ok(CholeskyFactor { n: a.dim(), kind })
    }
}

impl CholeskyFactor {
    pub fn dim(&self) -> usize {
        self.n
    }
    /// Solves `A x = b` in place (`rhs` holds `b` on entry, `x` on exit).
    pub fn solve_in_place(&self, rhs: &mut [f64]) {
        assert_eq!(rhs.len(), self.n, "right-hand side length");
        self.solve_many_in_place(rhs, 1);
    }
    /// Solves for several right-hand sides stored column-major (`n × k`).
    pub fn solve_many_in_place(&self, rhs: &mut [f64], k: usize) {
        assert_eq!(rhs.len(), self.n * k, "right-hand side length");
        match &self.kind {
            FactorKind::Single { domain, values } => {
                debug_assert_eq!(domain.dim(), self.n);
                domain.solve_in_place(values, rhs, k);
            }
            FactorKind::Scalar { symbolic, values } => {
                let par = Par::Seq;
                let mut mem = MemBuffer::new(symbolic.solve_in_place_scratch::<f64>(k, par));
                LltRef::new(symbolic, values).solve_in_place_with_conj(
                    Conj::No,
                    MatMut::from_column_major_slice_mut(rhs, self.n, k),
                    par,
                    MemStack::new(&mut mem),
                );
            }
            FactorKind::TwoDomain(f) => {
                debug_assert_eq!(f.dim(), self.n);
                for column in rhs.chunks_exact_mut(self.n) {
                    f.solve_in_place(column);
                }
            }
        }
    }
}
