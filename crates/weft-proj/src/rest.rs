//! What both layers need from the rest mesh: edges, rest lengths and the per-vertex
//! zero-length spring weights `k_i ∝ m_i` (Geng et al. §3: proportional to the lumped
//! vertex mass so that accelerations are more uniform).

use nalgebra::Vector3;
use weft_mesh::{Topology, TriMesh, geometry};

use crate::error::{Error, Result, check_finite, check_len};

/// Validated rest-state data shared by the projection layers.
#[derive(Debug, Clone)]
pub struct RestShape {
    num_vertices: usize,
    topology: Topology,
    rest_positions: Vec<Vector3<f64>>,
    rest_lengths: Vec<f64>,
    weights: Vec<f64>,
}

impl RestShape {
    /// Extracts edges, rest lengths and lumped-mass weights; fails on a zero-length rest
    /// edge or a vertex without mass.
    pub fn new(rest: &TriMesh) -> Result<Self> {
        let topology = Topology::new(rest);
        let p = rest.positions();
        let scale = rest.bounding_box_diagonal();
        let mut rest_lengths = Vec::with_capacity(topology.edges.len());
        for (edge, &[a, b]) in topology.edges.iter().enumerate() {
            let length = (p[a] - p[b]).norm();
            // A rest edge shorter than round-off of the mesh's size cannot carry a length bound.
            if !(length > 1e-12 * scale) {
                return Err(Error::DegenerateRestEdge { edge, a, b, length });
            }
            rest_lengths.push(length);
        }
        let masses = geometry::lumped_masses_tri(p, rest.faces(), 1.0);
        if let Some(vertex) = masses.iter().position(|m| !(*m > 0.0)) {
            return Err(Error::MasslessVertex { vertex });
        }
        // Geng et al. §3: only the relative k_i matter for the SOCP; normalise to mean 1.
        let mean = masses.iter().sum::<f64>() / masses.len() as f64;
        let weights = masses.iter().map(|m| m / mean).collect();
        Ok(Self {
            num_vertices: rest.num_vertices(),
            topology,
            rest_positions: p.to_vec(),
            rest_lengths,
            weights,
        })
    }

    pub fn num_vertices(&self) -> usize {
        self.num_vertices
    }
    pub fn topology(&self) -> &Topology {
        &self.topology
    }
    pub fn edges(&self) -> &[[usize; 2]] {
        &self.topology.edges
    }
    pub fn rest_positions(&self) -> &[Vector3<f64>] {
        &self.rest_positions
    }
    /// Rest length of every edge (m), in the order of [`RestShape::edges`].
    pub fn rest_lengths(&self) -> &[f64] {
        &self.rest_lengths
    }
    /// Lumped vertex masses of the rest mesh divided by their mean (dimensionless).
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Checks a flat prediction `[x0, y0, z0, x1, …]`: length `3 V` and finite.
    pub fn check_positions(&self, what: &'static str, x: &[f64]) -> Result<()> {
        check_len(what, x, 3 * self.num_vertices)?;
        check_finite(what, x)
    }
}

/// Distance between vertices `a` and `b` of a flat position vector.
#[inline]
pub(crate) fn edge_vector(x: &[f64], a: usize, b: usize) -> Vector3<f64> {
    Vector3::new(
        x[3 * a] - x[3 * b],
        x[3 * a + 1] - x[3 * b + 1],
        x[3 * a + 2] - x[3 * b + 2],
    )
}
