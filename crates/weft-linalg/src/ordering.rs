//! Fill-reducing orderings and graph separators on the *vertex* graph of a pattern of
//! `3 × 3` blocks (a third of the unknowns to order, supernodes aligned with vertices).
//!
//! Two candidate orderings are built and compared by the fill of the vertex graph's
//! elimination tree (`Graph::best_order`): AMD, best on surface-like and compact
//! meshes, and a level-set (Cuthill–McKee-like) order from a pseudo-peripheral vertex,
//! which on elongated bodies — a beam, a limb — gives a banded factor with large dense
//! supernodes.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::SymbolicSparseColMat;

use crate::{Error, Result};

/// An undirected graph in compressed adjacency form (no self loops).
#[derive(Debug, Clone)]
pub(crate) struct Graph {
    offsets: Vec<usize>,
    neighbours: Vec<usize>,
}

impl Graph {
    /// From undirected edges `(u, v)` given once or twice, in any order.
    pub(crate) fn from_edges(n: usize, edges: impl Iterator<Item = (usize, usize)> + Clone) -> Self {
        let mut degree = vec![0usize; n];
        for (u, v) in edges.clone().filter(|(u, v)| u != v) {
            degree[u] += 1;
            degree[v] += 1;
        }
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0);
        for d in &degree {
            offsets.push(offsets.last().unwrap_or(&0) + d);
        }
        let mut fill = offsets[..n].to_vec();
        let mut neighbours = vec![0; offsets[n]];
        for (u, v) in edges.filter(|(u, v)| u != v) {
            neighbours[fill[u]] = v;
            fill[u] += 1;
            neighbours[fill[v]] = u;
            fill[v] += 1;
        }
        // Sort and deduplicate each list (an edge given twice appears twice).
        let mut compact_offsets = Vec::with_capacity(n + 1);
        compact_offsets.push(0);
        let mut compact = Vec::with_capacity(neighbours.len());
        for v in 0..n {
            let list = &mut neighbours[offsets[v]..offsets[v + 1]];
            list.sort_unstable();
            let mut last = usize::MAX;
            for &u in list.iter() {
                if u != last {
                    compact.push(u);
                    last = u;
                }
            }
            compact_offsets.push(compact.len());
        }
        Self {
            offsets: compact_offsets,
            neighbours: compact,
        }
    }

    pub(crate) fn len(&self) -> usize {
        self.offsets.len() - 1
    }

    pub(crate) fn neighbours(&self, v: usize) -> &[usize] {
        &self.neighbours[self.offsets[v]..self.offsets[v + 1]]
    }

    /// Breadth-first levels from `root` (`usize::MAX` for unreached vertices), and the
    /// vertices in visiting order.
    fn bfs(&self, root: usize) -> (Vec<usize>, Vec<usize>) {
        let mut level = vec![usize::MAX; self.len()];
        let mut order = Vec::with_capacity(self.len());
        level[root] = 0;
        order.push(root);
        let mut head = 0;
        while head < order.len() {
            let v = order[head];
            head += 1;
            for &u in self.neighbours(v) {
                if level[u] == usize::MAX {
                    level[u] = level[v] + 1;
                    order.push(u);
                }
            }
        }
        (level, order)
    }

    /// A pseudo-peripheral vertex of the component of `start` (George–Liu: repeat BFS
    /// from the farthest vertex of smallest degree while the eccentricity grows).
    fn pseudo_peripheral(&self, start: usize) -> usize {
        let mut root = start;
        let mut eccentricity = 0;
        for _ in 0..8 {
            let (level, order) = self.bfs(root);
            let last = order.last().map_or(0, |&v| level[v]);
            if last <= eccentricity && root != start {
                break;
            }
            eccentricity = last;
            let candidate = order
                .iter()
                .rev()
                .take_while(|&&v| level[v] == last)
                .min_by_key(|&&v| self.neighbours(v).len())
                .copied()
                .unwrap_or(root);
            if candidate == root {
                break;
            }
            root = candidate;
        }
        root
    }

    /// Level-set order over all components, each from a pseudo-peripheral vertex, with
    /// each vertex's level (levels of later components continue the count).
    pub(crate) fn level_order(&self) -> (Vec<usize>, Vec<usize>) {
        let n = self.len();
        let mut level = vec![usize::MAX; n];
        let mut order = Vec::with_capacity(n);
        let mut base = 0;
        for start in 0..n {
            if level[start] != usize::MAX {
                continue;
            }
            let root = self.pseudo_peripheral(start);
            let (component_level, component_order) = self.bfs(root);
            let mut top = 0;
            for &v in &component_order {
                level[v] = base + component_level[v];
                top = top.max(component_level[v]);
            }
            order.extend(component_order);
            base += top + 1;
        }
        (order, level)
    }

    /// The subgraph induced by `vertices` (renumbered in that order).
    pub(crate) fn induced(&self, vertices: &[usize]) -> Graph {
        let mut local = vec![usize::MAX; self.len()];
        for (i, &v) in vertices.iter().enumerate() {
            local[v] = i;
        }
        let edges: Vec<(usize, usize)> = vertices
            .iter()
            .enumerate()
            .flat_map(|(i, &v)| {
                let local = &local;
                self.neighbours(v)
                    .iter()
                    .filter_map(move |&u| (local[u] != usize::MAX && local[u] > i).then_some((i, local[u])))
            })
            .collect();
        Graph::from_edges(vertices.len(), edges.iter().copied())
    }

    /// Stored entries of the Cholesky factor of the vertex graph eliminated in `order`
    /// (a permutation of all vertices): from the elimination tree's column counts, in
    /// time proportional to that count. A `3 × 3`-block factor has about nine times as
    /// many; cheap enough to compare candidate orderings before any symbolic
    /// factorisation of the full matrix.
    pub(crate) fn factor_len(&self, order: &[usize]) -> usize {
        let n = self.len();
        debug_assert_eq!(order.len(), n);
        let mut position = vec![0usize; n];
        for (i, &v) in order.iter().enumerate() {
            position[v] = i;
        }
        let mut col_ptr = Vec::with_capacity(n + 1);
        col_ptr.push(0);
        let mut row_idx = Vec::with_capacity(self.neighbours.len() / 2 + n);
        for &v in order {
            let start = row_idx.len();
            row_idx.extend(
                self.neighbours(v)
                    .iter()
                    .map(|&u| position[u])
                    .filter(|&p| p < position[v]),
            );
            row_idx.push(position[v]);
            row_idx[start..].sort_unstable();
            col_ptr.push(row_idx.len());
        }
        let upper = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        let mut etree = vec![0isize; n];
        let mut counts = vec![0usize; n];
        let mut mem = MemBuffer::new(
            faer::sparse::linalg::cholesky::simplicial::prefactorize_symbolic_cholesky_scratch::<usize>(n, 0),
        );
        faer::sparse::linalg::cholesky::simplicial::prefactorize_symbolic_cholesky(
            &mut etree,
            &mut counts,
            upper.as_ref(),
            MemStack::new(&mut mem),
        );
        counts.iter().sum()
    }

    /// Of the level-set and AMD orders of this graph, the faster to factorise, with its
    /// factor's length: the banded one unless AMD's factor is over 20 % smaller — a
    /// banded factor's supernodes are whole cross-sections, dense blocks on which faer
    /// runs faster per entry, while on sheets AMD's factor is several times smaller.
    pub(crate) fn best_order(&self) -> Result<(Vec<usize>, usize)> {
        let (banded, _) = self.level_order();
        let amd = self.amd_order()?;
        let (lb, la) = (self.factor_len(&banded), self.factor_len(&amd));
        Ok(if 5 * la < 4 * lb { (amd, la) } else { (banded, lb) })
    }

    /// Approximate minimum degree order (faer's AMD) of the vertices.
    pub(crate) fn amd_order(&self) -> Result<Vec<usize>> {
        let n = self.len();
        if n == 0 {
            return Ok(Vec::new());
        }
        // AMD reads the pattern as symmetric: give it the upper triangle.
        let mut col_ptr = vec![0];
        let mut row_idx = Vec::new();
        for v in 0..n {
            row_idx.extend(self.neighbours(v).iter().filter(|&&u| u < v));
            row_idx.push(v);
            col_ptr.push(row_idx.len());
        }
        let graph = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        let mut perm = vec![0usize; n];
        let mut perm_inv = vec![0usize; n];
        let nnz = graph.row_idx().len();
        let mut mem = MemBuffer::new(faer::sparse::linalg::amd::order_scratch::<usize>(n, nnz));
        faer::sparse::linalg::amd::order(
            &mut perm,
            &mut perm_inv,
            graph.as_ref(),
            faer::sparse::linalg::amd::Control::default(),
            MemStack::new(&mut mem),
        )
        .map_err(|e| Error::Setup(format!("AMD ordering failed: {e:?}")))?;
        Ok(perm)
    }
}

/// A vertex separator splitting the graph into two parts with no edge between them.
#[derive(Debug, Clone)]
pub(crate) struct Bisection {
    /// The two parts, each in level-set order running *towards* the separator (so a
    /// banded elimination of a part ends next to the separator).
    pub(crate) parts: [Vec<usize>; 2],
    pub(crate) separator: Vec<usize>,
}

/// A level-set separator: the smallest BFS level whose removal leaves two parts of
/// 35–65 % of the vertices each. Edges join only equal or adjacent levels, so any level
/// separates the lower from the higher ones. `None` when no level qualifies or the
/// separator would exceed `max_fraction` of the vertices.
pub(crate) fn level_bisection(graph: &Graph, max_fraction: f64) -> Option<Bisection> {
    let n = graph.len();
    let (order, level) = graph.level_order();
    let levels = level.iter().copied().max()? + 1;
    let mut count = vec![0usize; levels];
    for &l in &level {
        count[l] += 1;
    }
    let mut below = 0;
    let mut best: Option<(usize, usize)> = None;
    let mut cut = 0;
    for (l, &size) in count.iter().enumerate() {
        let above = n - below - size;
        let balanced = below as f64 >= 0.35 * n as f64 && above as f64 >= 0.35 * n as f64;
        // Smallest separator, then the most even split.
        let imbalance = below.abs_diff(above);
        if balanced && best.is_none_or(|(s, d)| (size, imbalance) < (s, d)) {
            best = Some((size, imbalance));
            cut = l;
        }
        below += size;
    }
    let (size, _) = best?;
    if size as f64 > max_fraction * n as f64 {
        return None;
    }
    let lower: Vec<usize> = order.iter().copied().filter(|&v| level[v] < cut).collect();
    let mut upper: Vec<usize> = order.iter().copied().filter(|&v| level[v] > cut).collect();
    upper.reverse();
    let separator = order.iter().copied().filter(|&v| level[v] == cut).collect();
    Some(Bisection {
        parts: [lower, upper],
        separator,
    })
}
