//! Validated tetrahedral meshes.

use std::collections::HashMap;

use nalgebra::Vector3;

use crate::element::tet_signed_volume;
use crate::error::{Error, Result};
use crate::trimesh::{TriMesh, check_finite, check_indices};

/// A tetrahedral mesh: vertex positions (metres) and positively oriented tetrahedra.
///
/// A tet `[a, b, c, d]` is positively oriented when `det[b − a, c − a, d − a] > 0`.
/// Construction rejects empty meshes, non-finite coordinates, bad indices and any
/// inverted or zero-volume tetrahedron (relative to the mesh's scale), so every
/// `TetMesh` is a valid rest shape.
#[derive(Debug, Clone, PartialEq)]
pub struct TetMesh {
    positions: Vec<Vector3<f64>>,
    tets: Vec<[usize; 4]>,
}

/// The outer surface of a tet mesh as its own compact triangle mesh.
#[derive(Debug, Clone)]
pub struct BoundarySurface {
    /// Outward-oriented surface over its own vertex numbering.
    pub mesh: TriMesh,
    /// `volume_vertex[i]` is the tet-mesh vertex of surface vertex `i`.
    pub volume_vertex: Vec<usize>,
}

impl TetMesh {
    pub fn new(positions: Vec<Vector3<f64>>, tets: Vec<[usize; 4]>) -> Result<Self> {
        if positions.is_empty() {
            return Err(Error::NoVertices);
        }
        if tets.is_empty() {
            return Err(Error::NoElements { what: "tetrahedra" });
        }
        check_finite(&positions)?;
        check_indices("tetrahedron", &tets, positions.len())?;
        // "Zero" volume is judged against the mesh scale so that a millimetre mesh and
        // a kilometre mesh are treated alike.
        let diag = crate::trimesh::bounding_box_diagonal(&positions);
        let tiny = 1e-14 * diag.powi(3);
        for (i, t) in tets.iter().enumerate() {
            let v = tet_signed_volume(&positions[t[0]], &positions[t[1]], &positions[t[2]], &positions[t[3]]);
            if v.is_nan() || v <= tiny {
                return Err(Error::BadTetVolume { tet: i, volume: v });
            }
        }
        Ok(Self { positions, tets })
    }

    pub fn positions(&self) -> &[Vector3<f64>] {
        &self.positions
    }
    pub fn tets(&self) -> &[[usize; 4]] {
        &self.tets
    }
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }
    pub fn num_tets(&self) -> usize {
        self.tets.len()
    }
    pub fn flat_positions(&self) -> Vec<f64> {
        crate::trimesh::flatten(&self.positions)
    }

    /// Total volume (m³).
    pub fn volume(&self) -> f64 {
        self.tets
            .iter()
            .map(|t| {
                tet_signed_volume(
                    &self.positions[t[0]],
                    &self.positions[t[1]],
                    &self.positions[t[2]],
                    &self.positions[t[3]],
                )
            })
            .sum()
    }

    /// Boundary faces (those belonging to exactly one tet), oriented outward, over the
    /// tet mesh's vertex numbering.
    pub fn boundary_faces(&self) -> Vec<[usize; 3]> {
        let mut count: HashMap<[usize; 3], (usize, [usize; 3])> = HashMap::new();
        for t in &self.tets {
            let [a, b, c, d] = *t;
            // Outward faces of a positively oriented tet (face k is opposite vertex k).
            for f in [[b, c, d], [a, d, c], [a, b, d], [a, c, b]] {
                let mut key = f;
                key.sort_unstable();
                count.entry(key).and_modify(|e| e.0 += 1).or_insert((1, f));
            }
        }
        let mut faces: Vec<[usize; 3]> = count.into_values().filter(|(n, _)| *n == 1).map(|(_, f)| f).collect();
        faces.sort_unstable();
        faces
    }

    /// The boundary surface as a compact, outward-oriented [`TriMesh`].
    pub fn boundary_surface(&self) -> Result<BoundarySurface> {
        let faces = self.boundary_faces();
        let mut map = vec![usize::MAX; self.positions.len()];
        let mut volume_vertex = Vec::new();
        let faces: Vec<[usize; 3]> = faces
            .iter()
            .map(|f| {
                f.map(|v| {
                    if map[v] == usize::MAX {
                        map[v] = volume_vertex.len();
                        volume_vertex.push(v);
                    }
                    map[v]
                })
            })
            .collect();
        let positions = volume_vertex.iter().map(|&v| self.positions[v]).collect();
        Ok(BoundarySurface {
            mesh: TriMesh::new(positions, faces)?,
            volume_vertex,
        })
    }
}
