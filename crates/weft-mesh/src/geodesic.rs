//! Graph-geodesic distances (Dijkstra over mesh edges).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use nalgebra::Vector3;

use crate::error::{Error, Result};
use crate::topology::Adjacency;

#[derive(PartialEq)]
struct Item(f64, usize);
impl Eq for Item {}
impl PartialOrd for Item {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Item {
    fn cmp(&self, other: &Self) -> Ordering {
        // Min-heap on distance; distances are finite by construction.
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

/// Shortest edge-path length (m) from the nearest of `sources` to every vertex, over the
/// graph `adjacency` with Euclidean edge lengths. Unreachable vertices get `f64::INFINITY`.
/// This over-estimates the true surface geodesic by at most the usual graph-metric
/// factor (≈ 8 % on a regular grid), which is all NNWarp's geodesic feature needs.
pub fn geodesic_distances(positions: &[Vector3<f64>], adjacency: &Adjacency, sources: &[usize]) -> Result<Vec<f64>> {
    if adjacency.len() != positions.len() {
        return Err(Error::LengthMismatch {
            what: "adjacency vertices",
            expected: positions.len(),
            got: adjacency.len(),
        });
    }
    let mut dist = vec![f64::INFINITY; positions.len()];
    let mut heap = BinaryHeap::new();
    for &s in sources {
        if s >= positions.len() {
            return Err(Error::IndexOutOfRange {
                element: "geodesic source",
                index: s,
                vertex: s,
                num_vertices: positions.len(),
            });
        }
        dist[s] = 0.0;
        heap.push(Item(0.0, s));
    }
    while let Some(Item(d, v)) = heap.pop() {
        if d > dist[v] {
            continue;
        }
        for &w in adjacency.neighbors(v) {
            let nd = d + (positions[w] - positions[v]).norm();
            if nd < dist[w] {
                dist[w] = nd;
                heap.push(Item(nd, w));
            }
        }
    }
    Ok(dist)
}
