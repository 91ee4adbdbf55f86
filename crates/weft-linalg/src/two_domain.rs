//! Two-domain substructuring: a sparse Cholesky factorisation and solve that run on
//! both cores.
//!
//! faer's supernodal factorisation and solve are sequential over the elimination tree
//! (its `Par` only splits dense blocks, which at weft's sizes measured slower on this
//! project's 2-core machines). A vertex separator `S` splits the unknowns into two
//! interiors `I₁`, `I₂` with no coupling between them; ordering `[I₁, I₂, S]` gives
//!
//! ```text
//!     ⎡ A₁₁   0   B₁ ⎤         ⎡ L₁₁   0    0  ⎤
//! A = ⎢  0   A₂₂  B₂ ⎥ ,   L = ⎢  0   L₂₂   0  ⎥ ,  L_SS L_SSᵀ = A_SS − Σᵢ L_Sᵢ L_Sᵢᵀ .
//!     ⎣ B₁ᵀ  B₂ᵀ A_SS⎦         ⎣ L_S1 L_S2 L_SS⎦
//! ```
//!
//! Each domain `Mᵢ = [Aᵢᵢ Bᵢ; Bᵢᵀ A_SS]` is factorised by faer on its own thread (with the
//! separator last, so its factor holds `Lᵢᵢ`, `L_Sᵢ` and a trailing block `L̃ᵢ` with
//! `L̃ᵢL̃ᵢᵀ = A_SS − L_Sᵢ L_Sᵢᵀ`, which is positive definite because `A` is). The separator's
//! Schur complement is then the small dense `L̃₁L̃₁ᵀ + L̃₂L̃₂ᵀ − A_SS`. A solve runs the
//! forward substitutions of both interiors in parallel, the dense separator solve, then
//! both backward substitutions in parallel — each thread streaming half of the factor,
//! which is what bounds a solve (memory bandwidth, and it does scale to two cores).

use std::sync::{Arc, Mutex};

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{LltParams, LltRegularization};
use faer::linalg::matmul::triangular::BlockStructure;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
    factorize_symbolic_cholesky, supernodal::SymbolicSupernodalCholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Accum, Conj, Mat, MatMut, Par, Side, Spec};

use crate::ordering::{Bisection, Graph};

/// Elimination orders of both interiors and the vertex-graph factor length of each
/// domain (separator last). Each interior takes its level-set order — running towards
/// the separator, so the band ends next to it — unless AMD's factor is over 20 % smaller
/// (the rule of `Graph::best_order`).
pub(crate) fn plan(graph: &Graph, bisection: &Bisection) -> Result<([Vec<usize>; 2], [usize; 2])> {
    let separator = &bisection.separator;
    let one = |part: &Vec<usize>| -> Result<(Vec<usize>, usize)> {
        let domain_vertices: Vec<usize> = part.iter().chain(separator).copied().collect();
        let local = graph.induced(&domain_vertices);
        let amd_interior = graph.induced(part).amd_order()?;
        let tail = part.len()..domain_vertices.len();
        let banded: Vec<usize> = (0..domain_vertices.len()).collect();
        let amd: Vec<usize> = amd_interior.iter().copied().chain(tail).collect();
        let (lb, la) = (local.factor_len(&banded), local.factor_len(&amd));
        Ok(if 5 * la < 4 * lb {
            (amd_interior.iter().map(|&i| part[i]).collect(), la)
        } else {
            (part.clone(), lb)
        })
    };
    let (a, b) = rayon::join(|| one(&bisection.parts[0]), || one(&bisection.parts[1]));
    let ((oa, la), (ob, lb)) = (a?, b?);
    Ok(([oa, ob], [la, lb]))
}
use crate::{Error, Result, SymmetricMatrix, SymmetricPattern};

/// One domain `Mᵢ` over `[interior DOFs (fill-reducing order), separator DOFs]`, stored
/// already permuted (faer then factorises it in the identity order: no permutation of
/// `A` per factorisation). An undivided matrix is one domain without separator.
#[derive(Debug)]
pub(crate) struct Domain {
    /// Global DOF of each local DOF.
    dofs: Vec<usize>,
    /// Local DOFs `0..interior` are the interior; the rest are the separator's.
    interior: usize,
    /// The domain matrix's structure, lower triangle (what faer's numeric factorisation
    /// reads without transposing).
    local: SymbolicSparseColMat<usize>,
    /// The slot in `A` of each local stored entry (the domain's values are gathered).
    gather: Vec<usize>,
    symbolic: SymbolicCholesky<usize>,
    /// Numeric buffers of dropped factors and faer's scratch, reused.
    buffers: Arc<Buffers>,
    /// The scratch a numeric factorisation needs (computed once: faer walks the
    /// supernodes to size it).
    scratch: faer::dyn_stack::StackReq,
}

/// Buffers a domain's numeric factorisations reuse: the values of dropped factors (a
/// factor's [`FactorValues`] returns them on drop) and faer's scratch. A factor of a
/// paper-size cloth matrix is 10–20 MB; allocating it afresh for each factorisation
/// costs a page fault per 4 KiB page when the allocator has returned the memory to the
/// system, and Newton factorises several times a step. faer zero-fills the values
/// itself, so a reused buffer gives the same factor bit for bit.
pub(crate) struct Buffers {
    len: usize,
    values: Mutex<Vec<Vec<f64>>>,
    scratch: Mutex<Vec<MemBuffer>>,
}

impl std::fmt::Debug for Buffers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Buffers")
            .field("len", &self.len)
            .finish_non_exhaustive()
    }
}

/// Bytes of dropped factors' values kept per domain, at most (more are freed), and the
/// most buffers kept whatever their size: enough for the factors a training batch holds
/// between its forward and backward passes (one per example) at paper size.
const KEPT_BYTES: usize = 256 << 20;
const KEPT_BUFFERS: usize = 16;

impl Buffers {
    fn new(len: usize) -> Arc<Self> {
        Arc::new(Self {
            len,
            values: Mutex::new(Vec::new()),
            scratch: Mutex::new(Vec::new()),
        })
    }

    fn take_values(self: &Arc<Self>) -> FactorValues {
        let kept = self.values.lock().ok().and_then(|mut v| v.pop());
        FactorValues {
            values: kept.unwrap_or_else(|| vec![0.0; self.len]),
            buffers: self.clone(),
        }
    }

    fn with_scratch<T>(&self, bytes: faer::dyn_stack::StackReq, f: impl FnOnce(&mut MemStack) -> T) -> T {
        let kept = self.scratch.lock().ok().and_then(|mut v| v.pop());
        let mut mem = kept.unwrap_or_else(|| MemBuffer::new(bytes));
        let out = f(MemStack::new(&mut mem));
        if let Ok(mut v) = self.scratch.lock() {
            if v.len() < 2 {
                v.push(mem);
            }
        }
        out
    }
}

/// A domain factor's numeric values, returned to the domain's [`Buffers`] when dropped.
#[derive(Debug)]
pub(crate) struct FactorValues {
    values: Vec<f64>,
    buffers: Arc<Buffers>,
}

impl Clone for FactorValues {
    fn clone(&self) -> Self {
        let mut copy = self.buffers.take_values();
        copy.values.copy_from_slice(&self.values);
        copy
    }
}

impl Drop for FactorValues {
    fn drop(&mut self) {
        let values = std::mem::take(&mut self.values);
        if values.len() == self.buffers.len {
            let limit = (KEPT_BYTES / (8 * self.buffers.len).max(1)).clamp(2, KEPT_BUFFERS);
            if let Ok(mut v) = self.buffers.values.lock() {
                if v.len() < limit {
                    v.push(values);
                }
            }
        }
    }
}

impl std::ops::Deref for FactorValues {
    type Target = [f64];
    fn deref(&self) -> &[f64] {
        &self.values
    }
}

/// The symbolic part: domains, their symbolic factors and the separator.
#[derive(Debug)]
pub(crate) struct TwoDomain {
    n: usize,
    domains: [Domain; 2],
    /// Global DOFs of the separator, in the order of the domains' trailing blocks.
    separator_dofs: Vec<usize>,
    /// `(i, j, global slot)` of the stored entries of `A_SS` (separator-local `i`, `j`).
    separator_entries: Vec<(usize, usize, usize)>,
}

/// The numeric factor.
#[derive(Debug, Clone)]
pub(crate) struct TwoDomainFactor {
    structure: Arc<TwoDomain>,
    values: [FactorValues; 2],
    schur: Arc<faer::linalg::solvers::Llt<f64>>,
}

fn supernodal(symbolic: &SymbolicCholesky<usize>) -> Result<&SymbolicSupernodalCholesky<usize>> {
    match symbolic.raw() {
        SymbolicCholeskyRaw::Supernodal(s) => Ok(s),
        SymbolicCholeskyRaw::Simplicial(_) => Err(Error::Setup("expected a supernodal factor".into())),
    }
}

impl Domain {
    /// Builds the domain over `interior` vertices (already in elimination order) and the
    /// separator vertices, with `A`'s pattern `pattern`.
    pub(crate) fn new(
        pattern: &SymmetricPattern,
        graph: &Graph,
        interior: &[usize],
        separator: &[usize],
    ) -> Result<Self> {
        let vertices: Vec<usize> = interior.iter().chain(separator).copied().collect();
        let mut local_vertex = vec![usize::MAX; graph.len()];
        for (i, &v) in vertices.iter().enumerate() {
            local_vertex[v] = i;
        }
        // The local pattern, column by column, with each entry's global slot. faer's
        // symbolic analysis in the identity order reads an upper triangle; its supernodal
        // numeric factorisation reads the lower one (handed the upper, it transposes it on
        // every factorisation), so the domain keeps the lower triangle for the numeric
        // work. Column `3lv + j` of local vertex `lv`: upper — the coupled local vertices
        // `lu < lv` (three DOF rows each), then its own block's upper part; lower — its
        // own block's lower part, then the coupled `lu > lv` (`block_slots` reads either
        // triangle).
        let n = 3 * vertices.len();
        let missing = || Error::Setup("vertex block missing from the pattern".into());
        let build = |lower: bool| -> Result<(Vec<usize>, Vec<usize>, Vec<usize>)> {
            let mut col_ptr = Vec::with_capacity(n + 1);
            col_ptr.push(0);
            let mut row_idx = Vec::new();
            let mut gather = Vec::new();
            let mut rows = Vec::new();
            for (lv, &gv) in vertices.iter().enumerate() {
                rows.clear();
                rows.extend(
                    graph
                        .neighbours(gv)
                        .iter()
                        .map(|&u| local_vertex[u])
                        .filter(|&lu| lu != usize::MAX && if lower { lu > lv } else { lu < lv }),
                );
                rows.sort_unstable();
                let blocks = rows
                    .iter()
                    .map(|&lu| pattern.block_slots(vertices[lu], gv).ok_or_else(missing))
                    .collect::<Result<Vec<_>>>()?;
                let own = pattern.block_slots(gv, gv).ok_or_else(missing)?;
                for j in 0..3 {
                    let coupled = |row_idx: &mut Vec<usize>, gather: &mut Vec<usize>| {
                        for (&lu, block) in rows.iter().zip(&blocks) {
                            for (i, slots) in block.iter().enumerate() {
                                row_idx.push(3 * lu + i);
                                gather.push(slots[j]);
                            }
                        }
                    };
                    let own_rows = if lower { j..3 } else { 0..j + 1 };
                    if !lower {
                        coupled(&mut row_idx, &mut gather);
                    }
                    for i in own_rows {
                        row_idx.push(3 * lv + i);
                        gather.push(own[i][j]);
                    }
                    if lower {
                        coupled(&mut row_idx, &mut gather);
                    }
                    col_ptr.push(row_idx.len());
                }
            }
            Ok((col_ptr, row_idx, gather))
        };
        let (upper_ptr, upper_rows, _) = build(false)?;
        let (col_ptr, row_idx, gather) = build(true)?;
        let dofs: Vec<usize> = vertices.iter().flat_map(|&v| [3 * v, 3 * v + 1, 3 * v + 2]).collect();
        let upper = SymbolicSparseColMat::new_checked(n, n, upper_ptr, None, upper_rows);
        let local = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        let symbolic = factorize_symbolic_cholesky(
            upper.as_ref(),
            Side::Upper,
            SymmetricOrdering::Identity,
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                ..Default::default()
            },
        )
        .map_err(|e| Error::Setup(format!("{e:?}")))?;
        supernodal(&symbolic)?;
        Ok(Self {
            dofs,
            interior: 3 * interior.len(),
            local,
            gather,
            buffers: Buffers::new(symbolic.len_val()),
            scratch: symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            symbolic,
        })
    }

    pub(crate) fn factor_len(&self) -> usize {
        self.symbolic.len_val()
    }

    /// The numeric factor of the domain's matrix, in a reused buffer where one is free.
    pub(crate) fn factorize_numeric(&self, a: &SymmetricMatrix) -> Result<FactorValues> {
        let local_values: Vec<f64> = self.gather.iter().map(|&g| a.values[g]).collect();
        let mut values = self.buffers.take_values();
        let params: Spec<LltParams, f64> = Default::default();
        self.buffers
            .with_scratch(self.scratch, |stack| {
                self.symbolic.factorize_numeric_llt::<f64>(
                    &mut values.values,
                    SparseColMatRef::new(self.local.as_ref(), &local_values),
                    Side::Lower,
                    LltRegularization::default(),
                    Par::Seq,
                    stack,
                    params,
                )
            })
            .map_err(|_| Error::NotPositiveDefinite)?;
        Ok(values)
    }

    /// The numeric factor of `Mᵢ` and its dense trailing block `L̃ᵢ` (lower triangular).
    fn factorize(&self, a: &SymmetricMatrix) -> Result<(FactorValues, Mat<f64>)> {
        let values = self.factorize_numeric(a)?;
        let s = self.dofs.len() - self.interior;
        let mut trailing = Mat::<f64>::zeros(s, s);
        let sym = supernodal(&self.symbolic)?;
        for_each_supernode(sym, &values, |begin, end, pattern, val| {
            let (c, r) = (end - begin, end - begin + pattern.len());
            for j in begin.max(self.interior)..end {
                let col = &val[(j - begin) * r..][..r];
                for (k, &l) in col.iter().enumerate().skip(j - begin) {
                    let row = if k < c { begin + k } else { pattern[k - c] };
                    trailing[(row - self.interior, j - self.interior)] = l;
                }
            }
        });
        Ok((values, trailing))
    }

    /// Solves the whole domain's system (for an undivided matrix: a domain without
    /// separator) with faer's supernodal solve, `k` right-hand sides column-major.
    pub(crate) fn solve_in_place(&self, values: &[f64], rhs: &mut [f64], k: usize) {
        let n = self.dofs.len();
        let mut local = vec![0.0; n * k];
        for c in 0..k {
            for (l, &g) in self.dofs.iter().enumerate() {
                local[c * n + l] = rhs[c * n + g];
            }
        }
        let mut mem = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(k, Par::Seq));
        LltRef::new(&self.symbolic, values).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(&mut local, n, k),
            Par::Seq,
            MemStack::new(&mut mem),
        );
        for c in 0..k {
            for (l, &g) in self.dofs.iter().enumerate() {
                rhs[c * n + g] = local[c * n + l];
            }
        }
    }

    pub(crate) fn dim(&self) -> usize {
        self.dofs.len()
    }

    /// Forward substitution over the interior columns: on exit `y[..interior]` holds
    /// `Lᵢᵢ⁻¹ bᵢ` and `y[interior..]` has had `L_Sᵢ Lᵢᵢ⁻¹ bᵢ` subtracted.
    fn forward(&self, values: &[f64], y: &mut [f64]) {
        // Compiled for the widest SIMD the CPU has (pulp dispatches at run time; the
        // workspace targets baseline x86-64): a memory-streaming loop wants wide loads.
        pulp::Arch::new().dispatch(|| self.forward_impl(values, y))
    }

    #[inline(always)]
    fn forward_impl(&self, values: &[f64], y: &mut [f64]) {
        let sym = supernodal(&self.symbolic).unwrap_or_else(|_| unreachable!("checked in new"));
        let mut t = Vec::new();
        for_each_supernode(sym, values, |begin, end, pattern, val| {
            if begin >= self.interior {
                return;
            }
            let (c, r) = (end - begin, end - begin + pattern.len());
            t.clear();
            t.resize(pattern.len(), 0.0);
            let jend = end.min(self.interior);
            // The diagonal block first, then the rows below it as one blocked update
            // `t = L_bot y_top`, four columns per pass over `t` (four memory streams).
            for j in begin..jend {
                let col = &val[(j - begin) * r..][..r];
                let yj = y[j] / col[j - begin];
                y[j] = yj;
                axpy(-yj, &col[j - begin + 1..c], &mut y[j + 1..end]);
            }
            let mut j = begin;
            while j + 4 <= jend {
                let k = j - begin;
                let cols = [0, 1, 2, 3].map(|q| &val[(k + q) * r + c..(k + q + 1) * r]);
                let a = [y[j], y[j + 1], y[j + 2], y[j + 3]];
                axpy4(a, cols, &mut t);
                j += 4;
            }
            for j in j..jend {
                let k = j - begin;
                axpy(y[j], &val[k * r + c..(k + 1) * r], &mut t);
            }
            for (&row, &tk) in pattern.iter().zip(&t) {
                y[row] -= tk;
            }
        });
    }

    /// Backward substitution over the interior columns, with the separator's values
    /// already in `y[interior..]`.
    fn backward(&self, values: &[f64], y: &mut [f64]) {
        pulp::Arch::new().dispatch(|| self.backward_impl(values, y))
    }

    #[inline(always)]
    fn backward_impl(&self, values: &[f64], y: &mut [f64]) {
        let sym = supernodal(&self.symbolic).unwrap_or_else(|_| unreachable!("checked in new"));
        let mut t = Vec::new();
        for s in (0..sym.n_supernodes()).rev() {
            let (begin, end, pattern, val) = supernode(sym, values, s);
            if begin >= self.interior {
                continue;
            }
            let (c, r) = (end - begin, end - begin + pattern.len());
            t.clear();
            t.extend(pattern.iter().map(|&row| y[row]));
            let jend = end.min(self.interior);
            // The rows below the diagonal block only meet the known `t`: all their dot
            // products first (four columns per pass), then the triangular block.
            let mut j = begin;
            while j + 4 <= jend {
                let k = j - begin;
                let cols = [0, 1, 2, 3].map(|q| &val[(k + q) * r + c..(k + q + 1) * r]);
                let d = dot4(cols, &t);
                for q in 0..4 {
                    y[j + q] -= d[q];
                }
                j += 4;
            }
            for j in j..jend {
                let k = j - begin;
                y[j] -= dot(&val[k * r + c..(k + 1) * r], &t);
            }
            for j in (begin..jend).rev() {
                let col = &val[(j - begin) * r..][..r];
                y[j] = (y[j] - dot(&col[j - begin + 1..c], &y[j + 1..end])) / col[j - begin];
            }
        }
    }
}

/// `y += a x` (vectorises: no reduction).
#[inline(always)]
fn axpy(a: f64, x: &[f64], y: &mut [f64]) {
    for (yi, &xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

/// `t += Σ_q a_q x_q` over four columns in one pass.
#[inline(always)]
fn axpy4(a: [f64; 4], x: [&[f64]; 4], t: &mut [f64]) {
    let n = t.len();
    let [x0, x1, x2, x3] = x.map(|x| &x[..n]);
    for i in 0..n {
        t[i] += a[0] * x0[i] + a[1] * x1[i] + a[2] * x2[i] + a[3] * x3[i];
    }
}

/// `[x_qᵀ t]` for four columns in one pass over `t`, each with four partial sums.
#[inline(always)]
fn dot4(x: [&[f64]; 4], t: &[f64]) -> [f64; 4] {
    let n = t.len();
    let [x0, x1, x2, x3] = x.map(|x| &x[..n]);
    let mut acc = [[0.0f64; 4]; 4];
    let chunks = n / 4;
    for b in 0..chunks {
        for l in 0..4 {
            let i = 4 * b + l;
            let ti = t[i];
            acc[0][l] += x0[i] * ti;
            acc[1][l] += x1[i] * ti;
            acc[2][l] += x2[i] * ti;
            acc[3][l] += x3[i] * ti;
        }
    }
    let mut out = acc.map(|a| a.iter().sum::<f64>());
    for i in 4 * chunks..n {
        out[0] += x0[i] * t[i];
        out[1] += x1[i] * t[i];
        out[2] += x2[i] * t[i];
        out[3] += x3[i] * t[i];
    }
    out
}

/// `xᵀy` with eight independent partial sums, so the loop is bound by memory rather
/// than by the latency of one chain of floating-point additions (the backward
/// substitution is a stream of such dot products).
#[inline(always)]
fn dot(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().min(y.len());
    let (x, y) = (&x[..n], &y[..n]);
    let mut acc = [0.0f64; 8];
    let (xc, yc) = (x.chunks_exact(8), y.chunks_exact(8));
    let (xr, yr) = (xc.remainder(), yc.remainder());
    for (a, b) in xc.zip(yc) {
        for k in 0..8 {
            acc[k] += a[k] * b[k];
        }
    }
    let tail: f64 = xr.iter().zip(yr).map(|(a, b)| a * b).sum();
    acc.iter().sum::<f64>() + tail
}

/// Supernode `s`: its column range, off-diagonal row pattern and column-major values.
#[inline(always)]
fn supernode<'a>(
    sym: &'a SymbolicSupernodalCholesky<usize>,
    values: &'a [f64],
    s: usize,
) -> (usize, usize, &'a [usize], &'a [f64]) {
    let begin = sym.supernode_begin()[s];
    let end = sym.supernode_end()[s];
    let pattern = sym.supernode(s).pattern();
    let vp = sym.col_ptr_for_val();
    (begin, end, pattern, &values[vp[s]..vp[s + 1]])
}

#[inline(always)]
fn for_each_supernode(
    sym: &SymbolicSupernodalCholesky<usize>,
    values: &[f64],
    mut f: impl FnMut(usize, usize, &[usize], &[f64]),
) {
    for s in 0..sym.n_supernodes() {
        let (begin, end, pattern, val) = supernode(sym, values, s);
        f(begin, end, pattern, val);
    }
}

impl TwoDomain {
    /// Builds both domains from [`plan`]'s interior orders.
    pub(crate) fn new(
        pattern: &SymmetricPattern,
        graph: &Graph,
        interiors: [Vec<usize>; 2],
        separator: &[usize],
    ) -> Result<Self> {
        let [i0, i1] = interiors;
        let (d0, d1) = rayon::join(
            || Domain::new(pattern, graph, &i0, separator),
            || Domain::new(pattern, graph, &i1, separator),
        );
        let separator_dofs: Vec<usize> = separator.iter().flat_map(|&v| [3 * v, 3 * v + 1, 3 * v + 2]).collect();
        let nv = pattern.dim() / 3;
        let mut sep_index = vec![usize::MAX; nv];
        for (i, &v) in separator.iter().enumerate() {
            sep_index[v] = i;
        }
        let separator_entries = pattern
            .entries()
            .filter_map(|(slot, r, c)| {
                let (sr, sc) = (sep_index[r / 3], sep_index[c / 3]);
                (sr != usize::MAX && sc != usize::MAX).then_some((3 * sr + r % 3, 3 * sc + c % 3, slot))
            })
            .collect();
        Ok(Self {
            n: pattern.dim(),
            domains: [d0?, d1?],
            separator_dofs,
            separator_entries,
        })
    }

    /// Stored entries of both domain factors plus the dense separator factor.
    pub(crate) fn factor_len(&self) -> usize {
        let s = self.separator_dofs.len();
        self.domains.iter().map(Domain::factor_len).sum::<usize>() + s * (s + 1) / 2
    }

    pub(crate) fn factorize(self: &Arc<Self>, a: &SymmetricMatrix) -> Result<TwoDomainFactor> {
        let (r0, r1) = rayon::join(|| self.domains[0].factorize(a), || self.domains[1].factorize(a));
        let ((v0, t0), (v1, t1)) = (r0?, r1?);
        // Schur complement of the separator: L̃₀L̃₀ᵀ + L̃₁L̃₁ᵀ − A_SS (lower triangle).
        let s = self.separator_dofs.len();
        let mut schur = Mat::<f64>::zeros(s, s);
        for (t, accum) in [(&t0, Accum::Replace), (&t1, Accum::Add)] {
            faer::linalg::matmul::triangular::matmul(
                schur.as_mut(),
                BlockStructure::TriangularLower,
                accum,
                t.as_ref(),
                BlockStructure::TriangularLower,
                t.transpose(),
                BlockStructure::TriangularUpper,
                1.0,
                Par::Seq,
            );
        }
        for &(i, j, slot) in &self.separator_entries {
            let (i, j) = (i.max(j), i.min(j));
            schur[(i, j)] -= a.values[slot];
        }
        let llt = schur.llt(Side::Lower).map_err(|_| Error::NotPositiveDefinite)?;
        Ok(TwoDomainFactor {
            structure: self.clone(),
            values: [v0, v1],
            schur: Arc::new(llt),
        })
    }
}

impl TwoDomainFactor {
    pub(crate) fn dim(&self) -> usize {
        self.structure.n
    }

    /// Solves `A x = b` in place for one right-hand side.
    pub(crate) fn solve_in_place(&self, rhs: &mut [f64]) {
        let st = &self.structure;
        let gather = |d: &Domain, rhs: &[f64]| -> Vec<f64> {
            let mut y = vec![0.0; d.dofs.len()];
            for (k, &g) in d.dofs[..d.interior].iter().enumerate() {
                y[k] = rhs[g];
            }
            y
        };
        let mut y0 = gather(&st.domains[0], rhs);
        let mut y1 = gather(&st.domains[1], rhs);
        rayon::join(
            || st.domains[0].forward(&self.values[0], &mut y0),
            || st.domains[1].forward(&self.values[1], &mut y1),
        );
        // Separator: (L_SS L_SSᵀ) x_S = b_S − Σᵢ L_Sᵢ zᵢ, the sum accumulated in the tails.
        let s = st.separator_dofs.len();
        let mut xs = Mat::<f64>::zeros(s, 1);
        let (i0, i1) = (st.domains[0].interior, st.domains[1].interior);
        for (k, &g) in st.separator_dofs.iter().enumerate() {
            xs[(k, 0)] = rhs[g] + y0[i0 + k] + y1[i1 + k];
        }
        faer::linalg::solvers::Solve::solve_in_place(self.schur.as_ref(), xs.as_mut());
        for k in 0..s {
            y0[i0 + k] = xs[(k, 0)];
            y1[i1 + k] = xs[(k, 0)];
        }
        rayon::join(
            || st.domains[0].backward(&self.values[0], &mut y0),
            || st.domains[1].backward(&self.values[1], &mut y1),
        );
        for (d, y) in st.domains.iter().zip([&y0, &y1]) {
            for (k, &g) in d.dofs[..d.interior].iter().enumerate() {
                rhs[g] = y[k];
            }
        }
        for (k, &g) in st.separator_dofs.iter().enumerate() {
            rhs[g] = xs[(k, 0)];
        }
    }
}
