//! Symmetric sparsity patterns (upper-triangle CSC with an index of `3 × 3` vertex blocks
//! for O(1) assembly) and the symmetric matrices stored over them.

use std::sync::Arc;

use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};

use crate::ordering::Graph;
use crate::{Error, Result};

/// The sparsity pattern of a symmetric `n × n` matrix: its upper triangle (diagonal
/// always included) in compressed-column form.
#[derive(Debug, Clone)]
pub struct SymmetricPattern {
    n: usize,
    pub(crate) symbolic: SymbolicSparseColMat<usize>,
    /// For patterns of `3 × 3` vertex blocks: per column vertex `v`, the row vertices
    /// `u ≤ v` (sorted) and the slot of row `3u` in each of the columns `3v..3v+3`.
    blocks: Option<VertexBlocks>,
}

#[derive(Debug, Clone)]
struct VertexBlocks {
    offsets: Vec<usize>,
    /// `u32`: the product streams these, and no pattern has 2³² entries.
    rows: Vec<u32>,
    slots: Vec<[u32; 3]>,
}

impl SymmetricPattern {
    /// Builds the pattern from off-diagonal (or diagonal) index pairs in any order and
    /// either triangle; duplicates are merged and the full diagonal is always present.
    pub fn new(n: usize, entries: impl IntoIterator<Item = (usize, usize)>) -> Self {
        let mut cols: Vec<Vec<usize>> = (0..n).map(|j| vec![j]).collect();
        for (r, c) in entries {
            assert!(r < n && c < n, "pattern entry ({r}, {c}) outside a {n} × {n} matrix");
            let (r, c) = if r <= c { (r, c) } else { (c, r) };
            cols[c].push(r);
        }
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        col_ptr.push(0);
        for mut col in cols {
            col.sort_unstable();
            col.dedup();
            row_idx.extend(col);
            col_ptr.push(row_idx.len());
        }
        let symbolic = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        Self {
            n,
            symbolic,
            blocks: None,
        }
    }

    /// Builds the pattern of a matrix made of dense `3 × 3` blocks coupling vertex pairs
    /// (the usual mesh DOF layout: vertex `v` owns DOFs `3v..3v+3`).
    pub fn from_vertex_pairs(num_vertices: usize, pairs: impl IntoIterator<Item = (usize, usize)>) -> Self {
        let mut entries = Vec::new();
        for v in 0..num_vertices {
            for a in 0..3 {
                for b in a..3 {
                    entries.push((3 * v + a, 3 * v + b));
                }
            }
        }
        for (u, v) in pairs {
            for a in 0..3 {
                for b in 0..3 {
                    entries.push((3 * u + a, 3 * v + b));
                }
            }
        }
        let mut pattern = Self::new(3 * num_vertices, entries);
        // Index the vertex blocks so assembly needs one short search per block.
        let mut offsets = vec![0];
        let mut rows = Vec::new();
        let mut slots = Vec::new();
        for v in 0..num_vertices {
            let c = 3 * v;
            let (start, end) = (pattern.col_ptr()[c], pattern.col_ptr()[c + 1]);
            for k in start..end {
                let r = pattern.row_idx()[k];
                if r % 3 == 0 {
                    let u = r / 3;
                    let base = |j: usize| {
                        let slot = pattern.slot(3 * u, c + j).expect("vertex blocks are dense");
                        u32::try_from(slot).expect("a pattern of fewer than 2³² entries")
                    };
                    rows.push(u32::try_from(u).expect("fewer than 2³² vertices"));
                    slots.push([base(0), base(1), base(2)]);
                }
            }
            offsets.push(rows.len());
        }
        pattern.blocks = Some(VertexBlocks { offsets, rows, slots });
        pattern
    }

    pub fn dim(&self) -> usize {
        self.n
    }
    pub fn nnz(&self) -> usize {
        self.symbolic.row_idx().len()
    }

    /// Slots of the `3 × 3` block at vertex pair `(u, v)` (either order) of a pattern of
    /// vertex blocks: `slots[i][j]` holds entry `(3u + i, 3v + j)` — one search per
    /// block, the DOF rows of a block being contiguous in each column.
    pub(crate) fn block_slots(&self, u: usize, v: usize) -> Option<[[usize; 3]; 3]> {
        let b = self.blocks.as_ref()?;
        let (ru, cv) = (u.min(v), u.max(v));
        let range = b.offsets[cv]..b.offsets[cv + 1];
        let k = b.rows[range.clone()].binary_search(&u32::try_from(ru).ok()?).ok()?;
        let base = b.slots[range.start + k].map(|s| s as usize);
        // Stored upper entry of (3u + i, 3v + j): row 3ru + r in column 3cv + c.
        Some([0, 1, 2].map(|i| {
            [0, 1, 2].map(|j| {
                let (r, c) = if u < v || (u == v && i <= j) { (i, j) } else { (j, i) };
                base[c] + r
            })
        }))
    }

    /// The vertex graph of a pattern of `3 × 3` vertex blocks.
    pub(crate) fn vertex_graph(&self) -> Option<Graph> {
        let b = self.blocks.as_ref()?;
        let nv = b.offsets.len() - 1;
        let edges = (0..nv).flat_map(move |v| {
            b.rows[b.offsets[v]..b.offsets[v + 1]]
                .iter()
                .map(move |&u| (u as usize, v))
        });
        Some(Graph::from_edges(nv, edges))
    }

    /// Storage slot of entry `(row, col)` (either triangle), or `None` if not in the pattern.
    pub fn slot(&self, row: usize, col: usize) -> Option<usize> {
        let (r, c) = if row <= col { (row, col) } else { (col, row) };
        let start = self.symbolic.col_ptr()[c];
        let end = self.symbolic.col_ptr()[c + 1];
        self.symbolic.row_idx()[start..end]
            .binary_search(&r)
            .ok()
            .map(|k| start + k)
    }

    /// Every stored entry as `(slot, row, col)` with `row <= col`.
    pub fn entries(&self) -> impl Iterator<Item = (usize, usize, usize)> + '_ {
        let (cp, ri) = (self.col_ptr(), self.row_idx());
        (0..self.n).flat_map(move |c| (cp[c]..cp[c + 1]).map(move |k| (k, ri[k], c)))
    }

    /// Whether `other` stores the same entries in the same slots (the same `Arc`, or
    /// equal index arrays).
    pub fn same_structure(&self, other: &SymmetricPattern) -> bool {
        std::ptr::eq(self, other)
            || (self.n == other.n && self.col_ptr() == other.col_ptr() && self.row_idx() == other.row_idx())
    }

    /// The slot of diagonal entry `(c, c)`: the last of column `c`, whose rows are sorted
    /// and at most `c` (the diagonal is always stored).
    fn diagonal_slot(&self, c: usize) -> usize {
        self.col_ptr()[c + 1] - 1
    }

    fn col_ptr(&self) -> &[usize] {
        self.symbolic.col_ptr()
    }
    fn row_idx(&self) -> &[usize] {
        self.symbolic.row_idx()
    }
}

/// A symmetric matrix over a shared [`SymmetricPattern`], upper triangle stored.
#[derive(Debug, Clone)]
pub struct SymmetricMatrix {
    pub(crate) pattern: Arc<SymmetricPattern>,
    pub(crate) values: Vec<f64>,
}

impl SymmetricMatrix {
    pub fn zeros(pattern: Arc<SymmetricPattern>) -> Self {
        let values = vec![0.0; pattern.nnz()];
        Self { pattern, values }
    }
    pub fn pattern(&self) -> &Arc<SymmetricPattern> {
        &self.pattern
    }
    pub fn dim(&self) -> usize {
        self.pattern.n
    }
    pub fn values(&self) -> &[f64] {
        &self.values
    }
    pub fn values_mut(&mut self) -> &mut [f64] {
        &mut self.values
    }
    pub fn set_zero(&mut self) {
        self.values.iter_mut().for_each(|v| *v = 0.0);
    }

    /// Adds `v` to entry `(row, col)` if `row <= col`; lower-triangle entries are
    /// ignored, so a caller may add a full symmetric block and each pair counts once.
    ///
    /// # Panics
    /// If `(row, col)` is not in the pattern: that is a bug in the caller's pattern.
    pub fn add(&mut self, row: usize, col: usize, v: f64) {
        if row <= col {
            let s = self
                .pattern
                .slot(row, col)
                .unwrap_or_else(|| panic!("entry ({row}, {col}) is not in the pattern"));
            self.values[s] += v;
        }
    }

    /// `self += other`, slot by slot: for adding a precomputed constant part of a matrix
    /// (e.g. a quadratic energy's Hessian) instead of assembling it again.
    pub fn add_matrix(&mut self, other: &SymmetricMatrix) -> Result<()> {
        if !self.pattern.same_structure(&other.pattern) {
            return Err(Error::PatternMismatch);
        }
        self.values.iter_mut().zip(&other.values).for_each(|(a, b)| *a += b);
        Ok(())
    }

    /// Adds `v` to the stored slot `slot` (from [`SymmetricPattern::slot`]).
    pub fn add_to_slot(&mut self, slot: usize, v: f64) {
        self.values[slot] += v;
    }

    /// Adds the `3 × 3` block `block` at vertex pair `(u, v)` — DOFs `3u..3u+3` by
    /// `3v..3v+3` — of a pattern built by [`SymmetricPattern::from_vertex_pairs`]. Only
    /// the part in the stored upper triangle is added (for `u == v`, its upper half;
    /// for `u > v`, nothing — the caller adds the transposed block at `(v, u)`). One
    /// binary search per column instead of one per entry: vertex DOFs are contiguous.
    pub fn add_vertex_block(&mut self, u: usize, v: usize, block: &[[f64; 3]; 3]) {
        if u > v {
            return;
        }
        let bases = match &self.pattern.blocks {
            Some(b) => {
                let range = b.offsets[v]..b.offsets[v + 1];
                let k = u32::try_from(u)
                    .ok()
                    .and_then(|u| b.rows[range.clone()].binary_search(&u).ok())
                    .unwrap_or_else(|| panic!("vertex block ({u}, {v}) is not in the pattern"));
                b.slots[range.start + k].map(|s| s as usize)
            }
            None => [0, 1, 2].map(|j| {
                self.pattern
                    .slot(3 * u, 3 * v + j)
                    .unwrap_or_else(|| panic!("vertex block ({u}, {v}) is not in the pattern"))
            }),
        };
        for (j, &base) in bases.iter().enumerate() {
            let rows = if u == v { j + 1 } else { 3 };
            for i in 0..rows {
                self.values[base + i] += block[i][j];
            }
        }
    }

    /// Adds a dense symmetric block over the DOF list `dofs` (row-major `dofs.len()²`).
    pub fn add_block(&mut self, dofs: &[usize], block: &[f64]) {
        let k = dofs.len();
        debug_assert_eq!(block.len(), k * k);
        for (a, &r) in dofs.iter().enumerate() {
            for (b, &c) in dofs.iter().enumerate() {
                self.add(r, c, block[a * k + b]);
            }
        }
    }

    /// Entry `(row, col)` (zero outside the pattern).
    pub fn get(&self, row: usize, col: usize) -> f64 {
        self.pattern.slot(row, col).map_or(0.0, |s| self.values[s])
    }

    /// `y = A x` using both triangles.
    ///
    /// On a pattern of vertex blocks the product runs block by block (one index per
    /// `3 × 3` block instead of one per entry, the three rows of a block column read as
    /// one contiguous triple), which is what conjugate gradients spend their time on;
    /// otherwise entry by entry.
    pub fn mul_vec(&self, x: &[f64], y: &mut [f64]) {
        let n = self.dim();
        assert!(x.len() == n && y.len() == n, "mul_vec dimension mismatch");
        if let Some(b) = &self.pattern.blocks {
            self.mul_vec_blocks(b, x, y);
            return;
        }
        y.iter_mut().for_each(|v| *v = 0.0);
        let (cp, ri) = (self.pattern.col_ptr(), self.pattern.row_idx());
        for c in 0..n {
            for k in cp[c]..cp[c + 1] {
                let r = ri[k];
                let v = self.values[k];
                y[r] += v * x[c];
                if r != c {
                    y[c] += v * x[r];
                }
            }
        }
    }

    /// [`mul_vec`](Self::mul_vec) over the vertex-block index: for column vertex `v`, the
    /// diagonal block `D_v` (upper triangle stored) and every block `B_uv`, `u < v`, whose
    /// column `j` holds rows `3u..3u+3` at `slots[j]..slots[j]+3`; `y_u += B x_v` and
    /// `y_v += Bᵀ x_u`.
    fn mul_vec_blocks(&self, b: &VertexBlocks, x: &[f64], y: &mut [f64]) {
        y.iter_mut().for_each(|v| *v = 0.0);
        let a = &self.values;
        for v in 0..b.offsets.len() - 1 {
            let xv = [x[3 * v], x[3 * v + 1], x[3 * v + 2]];
            let mut yv = [0.0; 3];
            for k in b.offsets[v]..b.offsets[v + 1] {
                let u = b.rows[k] as usize;
                let [s0, s1, s2] = b.slots[k].map(|s| s as usize);
                if u == v {
                    // Upper triangle: (0,0) | (0,1) (1,1) | (0,2) (1,2) (2,2).
                    let (d00, d01, d11, d02, d12, d22) = (a[s0], a[s1], a[s1 + 1], a[s2], a[s2 + 1], a[s2 + 2]);
                    yv[0] += d00 * xv[0] + d01 * xv[1] + d02 * xv[2];
                    yv[1] += d01 * xv[0] + d11 * xv[1] + d12 * xv[2];
                    yv[2] += d02 * xv[0] + d12 * xv[1] + d22 * xv[2];
                } else {
                    let (c0, c1, c2) = (&a[s0..s0 + 3], &a[s1..s1 + 3], &a[s2..s2 + 3]);
                    let xu = [x[3 * u], x[3 * u + 1], x[3 * u + 2]];
                    for i in 0..3 {
                        y[3 * u + i] += c0[i] * xv[0] + c1[i] * xv[1] + c2[i] * xv[2];
                    }
                    yv[0] += c0[0] * xu[0] + c0[1] * xu[1] + c0[2] * xu[2];
                    yv[1] += c1[0] * xu[0] + c1[1] * xu[1] + c1[2] * xu[2];
                    yv[2] += c2[0] * xu[0] + c2[1] * xu[1] + c2[2] * xu[2];
                }
            }
            for j in 0..3 {
                y[3 * v + j] += yv[j];
            }
        }
    }

    /// The `3 × 3` diagonal block of vertex `v` (both triangles), on a pattern of vertex
    /// blocks; `None` on another pattern.
    pub fn diagonal_block(&self, v: usize) -> Option<[[f64; 3]; 3]> {
        let s = self.pattern.block_slots(v, v)?;
        Some(s.map(|row| row.map(|slot| self.values[slot])))
    }

    /// Adds `shift` to every diagonal entry.
    pub fn add_diagonal(&mut self, shift: f64) {
        for c in 0..self.dim() {
            let s = self.pattern.diagonal_slot(c);
            self.values[s] += shift;
        }
    }

    /// The diagonal entries `A_ii`, in order.
    pub fn diagonal(&self) -> impl Iterator<Item = f64> + '_ {
        (0..self.dim()).map(|c| self.values[self.pattern.diagonal_slot(c)])
    }

    /// Copies `other`'s values, which must be over the same pattern (the same `Arc`).
    ///
    /// # Panics
    /// If the patterns differ: that is a bug in the caller.
    pub fn copy_values_from(&mut self, other: &SymmetricMatrix) {
        assert!(
            Arc::ptr_eq(&self.pattern, &other.pattern),
            "copy_values_from: another pattern"
        );
        self.values.copy_from_slice(&other.values);
    }

    /// Dirichlet elimination: zeroes every row and column of a DOF with `fixed[i]` and
    /// puts 1 on its diagonal, so a solve leaves those DOFs at their right-hand side
    /// (zero for a Newton step) without changing the free block.
    pub fn constrain_dofs(&mut self, fixed: &[bool]) {
        assert_eq!(fixed.len(), self.dim(), "fixed-DOF mask length");
        let pattern = self.pattern.clone();
        for (slot, r, c) in pattern.entries() {
            if fixed[r] || fixed[c] {
                self.values[slot] = if r == c { 1.0 } else { 0.0 };
            }
        }
    }

    pub(crate) fn check_finite(&self) -> Result<()> {
        if self.values.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(Error::NonFinite("matrix"))
        }
    }

    pub(crate) fn as_faer(&self) -> SparseColMatRef<'_, usize, f64> {
        SparseColMatRef::new(self.pattern.symbolic.as_ref(), &self.values)
    }
}
