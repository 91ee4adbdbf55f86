//! Connectivity derived from faces or tetrahedra: edges, hinges, rings, boundaries.

use std::collections::HashMap;

use crate::element::sorted2;
use crate::tetmesh::TetMesh;
use crate::trimesh::TriMesh;

pub use crate::element::unique_edges;

/// Compressed adjacency lists: `neighbors(i)` is sorted and excludes `i`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Adjacency {
    offsets: Vec<usize>,
    indices: Vec<usize>,
}

impl Adjacency {
    /// Builds from per-vertex lists (each sorted and deduplicated here).
    pub fn from_lists(lists: Vec<Vec<usize>>) -> Self {
        let mut offsets = Vec::with_capacity(lists.len() + 1);
        let mut indices = Vec::new();
        offsets.push(0);
        for mut l in lists {
            l.sort_unstable();
            l.dedup();
            indices.extend(l);
            offsets.push(indices.len());
        }
        Self { offsets, indices }
    }

    /// Builds the vertex graph of a set of undirected edges.
    pub fn from_edges(num_vertices: usize, edges: &[[usize; 2]]) -> Self {
        let mut lists = vec![Vec::new(); num_vertices];
        for &[a, b] in edges {
            lists[a].push(b);
            lists[b].push(a);
        }
        Self::from_lists(lists)
    }

    pub fn neighbors(&self, i: usize) -> &[usize] {
        &self.indices[self.offsets[i]..self.offsets[i + 1]]
    }
    pub fn len(&self) -> usize {
        self.offsets.len() - 1
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Total number of (i, j) entries.
    pub fn num_entries(&self) -> usize {
        self.indices.len()
    }
}

/// An interior edge with its two faces, as used by bending energies.
///
/// With faces `(x0, x1, opposite[0])` and `(x1, x0, opposite[1])` (both counter-clockwise),
/// `edge_vertices = [x0, x1]` follow the first face's orientation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hinge {
    pub edge: usize,
    pub edge_vertices: [usize; 2],
    pub opposite: [usize; 2],
    pub faces: [usize; 2],
}

/// Topology of a [`TriMesh`].
#[derive(Debug, Clone)]
pub struct Topology {
    /// Unique undirected edges `[a, b]`, `a < b`, sorted.
    pub edges: Vec<[usize; 2]>,
    /// For each edge, its one or two faces.
    pub edge_faces: Vec<[Option<usize>; 2]>,
    /// For each face, the edge between corner `k` and corner `k + 1`.
    pub face_edges: Vec<[usize; 3]>,
    /// Interior edges with their opposite vertices.
    pub hinges: Vec<Hinge>,
    /// Vertex 1-ring (edge neighbours).
    pub one_ring: Adjacency,
    /// Vertex 2-ring: vertices two edges away, excluding the vertex and its 1-ring.
    pub two_ring: Adjacency,
    /// Faces incident to each vertex.
    pub vertex_faces: Adjacency,
    /// Closed boundary loops as vertex cycles, each following the face orientation.
    pub boundary_loops: Vec<Vec<usize>>,
}

impl Topology {
    pub fn new(mesh: &TriMesh) -> Self {
        let faces = mesh.faces();
        let nv = mesh.num_vertices();
        let edges = unique_edges(faces);
        let index: HashMap<[usize; 2], usize> = edges.iter().enumerate().map(|(i, &e)| (e, i)).collect();

        let mut edge_faces = vec![[None, None]; edges.len()];
        let mut face_edges = Vec::with_capacity(faces.len());
        for (fi, f) in faces.iter().enumerate() {
            let mut fe = [0; 3];
            for k in 0..3 {
                let e = index[&sorted2(f[k], f[(k + 1) % 3])];
                fe[k] = e;
                let slot = &mut edge_faces[e];
                // TriMesh validation guarantees at most two faces per edge.
                if slot[0].is_none() {
                    slot[0] = Some(fi)
                } else {
                    slot[1] = Some(fi)
                }
            }
            face_edges.push(fe);
        }

        let mut hinges = Vec::new();
        for (e, ef) in edge_faces.iter().enumerate() {
            if let [Some(f0), Some(f1)] = *ef {
                let (x0, x1, o0) = oriented_edge(faces[f0], edges[e]);
                let o1 = faces[f1].iter().copied().find(|&v| v != x0 && v != x1).unwrap_or(x0);
                hinges.push(Hinge {
                    edge: e,
                    edge_vertices: [x0, x1],
                    opposite: [o0, o1],
                    faces: [f0, f1],
                });
            }
        }

        let one_ring = Adjacency::from_edges(nv, &edges);
        let two_ring = two_ring(&one_ring);
        let mut vf = vec![Vec::new(); nv];
        for (fi, f) in faces.iter().enumerate() {
            for &v in f {
                vf[v].push(fi);
            }
        }
        let vertex_faces = Adjacency::from_lists(vf);
        let boundary_loops = boundary_loops(faces, &edge_faces, &face_edges);
        Self {
            edges,
            edge_faces,
            face_edges,
            hinges,
            one_ring,
            two_ring,
            vertex_faces,
            boundary_loops,
        }
    }

    /// Edges with a single face.
    pub fn boundary_edges(&self) -> impl Iterator<Item = usize> + '_ {
        self.edge_faces
            .iter()
            .enumerate()
            .filter(|(_, f)| f[1].is_none())
            .map(|(e, _)| e)
    }

    /// `true` for vertices on a boundary edge.
    pub fn boundary_vertices(&self, num_vertices: usize) -> Vec<bool> {
        let mut b = vec![false; num_vertices];
        for e in self.boundary_edges() {
            b[self.edges[e][0]] = true;
            b[self.edges[e][1]] = true;
        }
        b
    }
}

/// The edge's endpoints in the order face `f` traverses them, and the third vertex.
fn oriented_edge(f: [usize; 3], e: [usize; 2]) -> (usize, usize, usize) {
    for k in 0..3 {
        let (a, b) = (f[k], f[(k + 1) % 3]);
        if sorted2(a, b) == e {
            return (a, b, f[(k + 2) % 3]);
        }
    }
    unreachable!("edge {e:?} is not in face {f:?}")
}

/// The 2-ring of every vertex: neighbours of neighbours, minus the vertex and its 1-ring.
pub fn two_ring(one_ring: &Adjacency) -> Adjacency {
    let n = one_ring.len();
    let mut mark = vec![usize::MAX; n];
    let lists = (0..n)
        .map(|i| {
            mark[i] = i;
            for &j in one_ring.neighbors(i) {
                mark[j] = i;
            }
            let mut out = Vec::new();
            for &j in one_ring.neighbors(i) {
                for &k in one_ring.neighbors(j) {
                    if mark[k] != i {
                        mark[k] = i;
                        out.push(k);
                    }
                }
            }
            out
        })
        .collect();
    Adjacency::from_lists(lists)
}

fn boundary_loops(
    faces: &[[usize; 3]],
    edge_faces: &[[Option<usize>; 2]],
    face_edges: &[[usize; 3]],
) -> Vec<Vec<usize>> {
    // Boundary half-edges directed as their face traverses them. At a non-manifold
    // ("bow-tie") vertex several start there; each is consumed once, so we never loop.
    let mut next: HashMap<usize, Vec<usize>> = HashMap::new();
    let mut count = 0;
    for (fi, f) in faces.iter().enumerate() {
        for k in 0..3 {
            if edge_faces[face_edges[fi][k]][1].is_none() {
                next.entry(f[k]).or_default().push(f[(k + 1) % 3]);
                count += 1;
            }
        }
    }
    let mut starts: Vec<usize> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut loops = Vec::new();
    let mut used = 0;
    for s in starts {
        while next.get(&s).is_some_and(|v| !v.is_empty()) {
            let mut cycle = vec![s];
            let mut v = s;
            while let Some(w) = next.get_mut(&v).and_then(Vec::pop) {
                used += 1;
                if w == s {
                    break;
                }
                cycle.push(w);
                v = w;
                if used > count {
                    break;
                }
            }
            loops.push(cycle);
        }
    }
    loops
}

/// Topology of a [`TetMesh`]: unique edges and the vertex graph.
#[derive(Debug, Clone)]
pub struct TetTopology {
    pub edges: Vec<[usize; 2]>,
    pub one_ring: Adjacency,
}

impl TetTopology {
    pub fn new(mesh: &TetMesh) -> Self {
        let mut edges: Vec<[usize; 2]> = mesh
            .tets()
            .iter()
            .flat_map(|t| [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)].map(|(a, b)| sorted2(t[a], t[b])))
            .collect();
        edges.sort_unstable();
        edges.dedup();
        let one_ring = Adjacency::from_edges(mesh.num_vertices(), &edges);
        Self { edges, one_ring }
    }
}
