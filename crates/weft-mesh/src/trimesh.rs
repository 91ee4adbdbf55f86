//! Validated triangle surface meshes.

use std::collections::HashMap;

use nalgebra::Vector3;

use crate::element::{face_areas, unique_edges};
use crate::error::{Error, Result};

/// A triangle mesh: vertex positions (metres) and counter-clockwise faces.
///
/// Construction validates everything later code relies on, so a `TriMesh` in hand is
/// always: non-empty, finite, in range, free of repeated indices in a face, edge-manifold
/// (at most two faces per edge) and consistently oriented (the two faces at an interior
/// edge traverse it in opposite directions). Zero-area faces are allowed here (a deformed
/// state may collapse one); geometry that needs area checks it with
/// [`TriMesh::check_face_areas`].
#[derive(Debug, Clone, PartialEq)]
pub struct TriMesh {
    positions: Vec<Vector3<f64>>,
    faces: Vec<[usize; 3]>,
}

impl TriMesh {
    /// Validates and builds a mesh.
    pub fn new(positions: Vec<Vector3<f64>>, faces: Vec<[usize; 3]>) -> Result<Self> {
        if positions.is_empty() {
            return Err(Error::NoVertices);
        }
        if faces.is_empty() {
            return Err(Error::NoElements { what: "faces" });
        }
        check_finite(&positions)?;
        check_indices("face", &faces, positions.len())?;
        check_edge_manifold(&faces)?;
        Ok(Self { positions, faces })
    }

    /// Builds a mesh from flat arrays (`3 * V` coordinates).
    pub fn from_flat(coords: &[f64], faces: Vec<[usize; 3]>) -> Result<Self> {
        if !coords.len().is_multiple_of(3) {
            return Err(Error::LengthMismatch {
                what: "flat coordinates (multiple of 3)",
                expected: coords.len() / 3 * 3,
                got: coords.len(),
            });
        }
        Self::new(unflatten(coords), faces)
    }

    /// The same connectivity with new vertex positions (e.g. a deformed frame).
    pub fn with_positions(&self, positions: Vec<Vector3<f64>>) -> Result<Self> {
        if positions.len() != self.positions.len() {
            return Err(Error::LengthMismatch {
                what: "vertex positions",
                expected: self.positions.len(),
                got: positions.len(),
            });
        }
        check_finite(&positions)?;
        Ok(Self {
            positions,
            faces: self.faces.clone(),
        })
    }

    pub fn positions(&self) -> &[Vector3<f64>] {
        &self.positions
    }
    pub fn faces(&self) -> &[[usize; 3]] {
        &self.faces
    }
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }
    pub fn num_faces(&self) -> usize {
        self.faces.len()
    }

    /// Positions as a flat `[x0, y0, z0, x1, ...]` vector, the layout solvers use.
    pub fn flat_positions(&self) -> Vec<f64> {
        flatten(&self.positions)
    }

    /// Errors on the first face whose area is at or below `tolerance` (m²).
    pub fn check_face_areas(&self, tolerance: f64) -> Result<()> {
        for (f, a) in face_areas(&self.positions, &self.faces).into_iter().enumerate() {
            if a.is_nan() || a <= tolerance {
                return Err(Error::DegenerateFace {
                    face: f,
                    area: a,
                    tolerance,
                });
            }
        }
        Ok(())
    }

    /// Total surface area (m²).
    pub fn area(&self) -> f64 {
        face_areas(&self.positions, &self.faces).iter().sum()
    }

    /// Euler characteristic V − E + F.
    pub fn euler_characteristic(&self) -> i64 {
        let edges = unique_edges(&self.faces).len();
        self.num_vertices() as i64 - edges as i64 + self.num_faces() as i64
    }

    /// Diagonal of the axis-aligned bounding box (m).
    pub fn bounding_box_diagonal(&self) -> f64 {
        bounding_box_diagonal(&self.positions)
    }
}

pub(crate) fn check_finite(positions: &[Vector3<f64>]) -> Result<()> {
    for (i, p) in positions.iter().enumerate() {
        if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
            return Err(Error::NonFiniteCoordinate {
                vertex: i,
                x: p.x,
                y: p.y,
                z: p.z,
            });
        }
    }
    Ok(())
}

pub(crate) fn check_indices<const N: usize>(
    element: &'static str,
    elements: &[[usize; N]],
    num_vertices: usize,
) -> Result<()> {
    for (index, e) in elements.iter().enumerate() {
        for (k, &v) in e.iter().enumerate() {
            if v >= num_vertices {
                return Err(Error::IndexOutOfRange {
                    element,
                    index,
                    vertex: v,
                    num_vertices,
                });
            }
            if e[..k].contains(&v) {
                return Err(Error::RepeatedIndex {
                    element,
                    index,
                    vertex: v,
                });
            }
        }
    }
    Ok(())
}

fn check_edge_manifold(faces: &[[usize; 3]]) -> Result<()> {
    // Directed half-edge counts: a manifold, consistently oriented surface uses each
    // directed edge at most once, and each undirected edge at most twice.
    let mut directed: HashMap<(usize, usize), usize> = HashMap::with_capacity(faces.len() * 3);
    for f in faces {
        for k in 0..3 {
            *directed.entry((f[k], f[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    let mut worst: Option<(usize, usize, usize)> = None;
    let mut flipped: Option<(usize, usize)> = None;
    for (&(a, b), &n) in &directed {
        let back = directed.get(&(b, a)).copied().unwrap_or(0);
        let total = n + back;
        if total > 2 {
            let key = (a.min(b), a.max(b), total);
            if worst.is_none_or(|w| (w.0, w.1) > (key.0, key.1)) {
                worst = Some(key);
            }
        } else if n > 1 {
            let key = (a.min(b), a.max(b));
            if flipped.is_none_or(|w| w > key) {
                flipped = Some(key);
            }
        }
    }
    if let Some((a, b, count)) = worst {
        return Err(Error::NonManifoldEdge { a, b, count });
    }
    if let Some((a, b)) = flipped {
        return Err(Error::InconsistentOrientation { a, b });
    }
    Ok(())
}

/// `[x0, y0, z0, x1, ...]` from points.
pub fn flatten(points: &[Vector3<f64>]) -> Vec<f64> {
    points.iter().flat_map(|p| [p.x, p.y, p.z]).collect()
}

/// Points from `[x0, y0, z0, x1, ...]` (a trailing partial triple is ignored).
pub fn unflatten(coords: &[f64]) -> Vec<Vector3<f64>> {
    coords.chunks_exact(3).map(|c| Vector3::new(c[0], c[1], c[2])).collect()
}

pub(crate) fn bounding_box_diagonal(points: &[Vector3<f64>]) -> f64 {
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (hi - lo).norm()
}
