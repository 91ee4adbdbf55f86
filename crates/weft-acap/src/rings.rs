//! The weighted 1-ring lists that the feature extractor, the consistency sweeps and the
//! Poisson inverse all walk: compressed rows built once per rest mesh. It is not a mesh
//! topology (weft-mesh's `Topology` is); it only carries the edge weights along.

use weft_mesh::Topology;

/// Weighted 1-ring lists in compressed form.
#[derive(Debug, Clone)]
pub(crate) struct Rings {
    offsets: Vec<usize>,
    neighbors: Vec<usize>,
    weights: Vec<f64>,
}

impl Rings {
    /// The 1-rings of `topology`, each neighbour weighted by its edge's entry in
    /// `edge_weight` (indexed like `topology.edges`).
    pub(crate) fn new(topology: &Topology, edge_weight: &[f64]) -> Self {
        let n = topology.one_ring.len();
        let mut offsets = Vec::with_capacity(n + 1);
        let mut neighbors = Vec::with_capacity(2 * topology.edges.len());
        let mut weights = Vec::with_capacity(2 * topology.edges.len());
        offsets.push(0);
        for i in 0..n {
            for &j in topology.one_ring.neighbors(i) {
                let key = [i.min(j), i.max(j)];
                let e = topology
                    .edges
                    .binary_search(&key)
                    .expect("1-ring neighbours are mesh edges");
                neighbors.push(j);
                weights.push(edge_weight[e]);
            }
            offsets.push(neighbors.len());
        }
        Self {
            offsets,
            neighbors,
            weights,
        }
    }
    pub(crate) fn len(&self) -> usize {
        self.offsets.len() - 1
    }
    pub(crate) fn neighbors(&self, i: usize) -> &[usize] {
        &self.neighbors[self.offsets[i]..self.offsets[i + 1]]
    }
    pub(crate) fn weights(&self, i: usize) -> &[f64] {
        &self.weights[self.offsets[i]..self.offsets[i + 1]]
    }
    /// One vertex per connected component: the lowest index in it.
    pub(crate) fn component_roots(&self) -> Vec<usize> {
        let n = self.len();
        let mut seen = vec![false; n];
        let mut roots = Vec::new();
        let mut stack = Vec::new();
        for s in 0..n {
            if seen[s] {
                continue;
            }
            roots.push(s);
            seen[s] = true;
            stack.push(s);
            while let Some(i) = stack.pop() {
                for &j in self.neighbors(i) {
                    if !seen[j] {
                        seen[j] = true;
                        stack.push(j);
                    }
                }
            }
        }
        roots
    }
}
