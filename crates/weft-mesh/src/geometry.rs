//! Geometric quantities of triangle and tetrahedral meshes.
//!
//! Functions take positions explicitly so they serve rest and deformed states alike.
//! Units: positions in metres, areas m², volumes m³, densities kg/m² (surfaces) or
//! kg/m³ (volumes), masses kg, angles radians.

use nalgebra::{Matrix3, Vector3};

use crate::error::{Error, Result};
use crate::topology::Topology;

pub use crate::element::{face_areas, tet_signed_volume, triangle_area};

/// Unit normal of counter-clockwise triangle `abc` (zero vector for a degenerate one).
pub fn triangle_normal(a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>) -> Vector3<f64> {
    (b - a)
        .cross(&(c - a))
        .try_normalize(0.0)
        .unwrap_or_else(Vector3::zeros)
}

pub fn face_normals(positions: &[Vector3<f64>], faces: &[[usize; 3]]) -> Vec<Vector3<f64>> {
    faces
        .iter()
        .map(|f| triangle_normal(&positions[f[0]], &positions[f[1]], &positions[f[2]]))
        .collect()
}

/// Area-weighted vertex normals (unit length; zero for a vertex with only degenerate faces).
pub fn vertex_normals(positions: &[Vector3<f64>], faces: &[[usize; 3]]) -> Vec<Vector3<f64>> {
    let mut n = vec![Vector3::zeros(); positions.len()];
    for f in faces {
        // The unnormalised cross product is twice the area times the normal.
        let w = (positions[f[1]] - positions[f[0]]).cross(&(positions[f[2]] - positions[f[0]]));
        for &v in f {
            n[v] += w;
        }
    }
    n.into_iter()
        .map(|v| v.try_normalize(0.0).unwrap_or_else(Vector3::zeros))
        .collect()
}

/// Lumped vertex masses of a surface: each face gives a third of `density · area` to each
/// corner. `density` in kg/m².
pub fn lumped_masses_tri(positions: &[Vector3<f64>], faces: &[[usize; 3]], density: f64) -> Vec<f64> {
    let mut m = vec![0.0; positions.len()];
    for (f, a) in faces.iter().zip(face_areas(positions, faces)) {
        for &v in f {
            m[v] += density * a / 3.0;
        }
    }
    m
}

/// `cot` of the angle at corner `a` of triangle `abc`.
fn cot_at(a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>) -> f64 {
    let (u, v) = (b - a, c - a);
    u.dot(&v) / u.cross(&v).norm()
}

/// Cotangent weights per edge of `topology`: `½(cot α + cot β)` over the angles opposite
/// the edge (one angle on a boundary edge). Fails on a zero-area face, where the
/// cotangent is undefined.
pub fn cotangent_weights(positions: &[Vector3<f64>], faces: &[[usize; 3]], topology: &Topology) -> Result<Vec<f64>> {
    let mut w = vec![0.0; topology.edges.len()];
    for (fi, f) in faces.iter().enumerate() {
        let area = triangle_area(&positions[f[0]], &positions[f[1]], &positions[f[2]]);
        if !(area > 0.0) {
            return Err(Error::DegenerateFace {
                face: fi,
                area,
                tolerance: 0.0,
            });
        }
        for k in 0..3 {
            // Edge (k, k+1) is opposite corner k+2.
            let c = cot_at(&positions[f[(k + 2) % 3]], &positions[f[k]], &positions[f[(k + 1) % 3]]);
            w[topology.face_edges[fi][k]] += 0.5 * c;
        }
    }
    Ok(w)
}

/// The cotangent Laplacian `L` as `(row, col, value)` triplets (duplicates summed by the
/// consumer): `L_ij = −w_ij`, `L_ii = Σ_j w_ij`, so every row sums to zero and `L` is
/// positive semi-definite on a Delaunay mesh.
pub fn cotangent_laplacian(
    positions: &[Vector3<f64>],
    faces: &[[usize; 3]],
    topology: &Topology,
) -> Result<Vec<(usize, usize, f64)>> {
    let w = cotangent_weights(positions, faces, topology)?;
    let mut t = Vec::with_capacity(4 * w.len());
    for (&[a, b], &wij) in topology.edges.iter().zip(&w) {
        t.extend([(a, b, -wij), (b, a, -wij), (a, a, wij), (b, b, wij)]);
    }
    Ok(t)
}

/// Signed dihedral angle at the hinge with edge `x0 → x1` shared by the counter-clockwise
/// faces `(x0, x1, x2)` and `(x1, x0, x3)`.
///
/// Zero when flat; in `(−π, π]`; the angle by which the second face's normal is rotated
/// from the first's about `x1 − x0`. It is negative for a valley (the faces fold towards
/// their normals: lifting `x3` along the first face's normal) and positive for a
/// mountain. Computed with `atan2`, so it is accurate near 0 and ±π.
pub fn dihedral_angle(x0: &Vector3<f64>, x1: &Vector3<f64>, x2: &Vector3<f64>, x3: &Vector3<f64>) -> f64 {
    let e = x1 - x0;
    let n1 = e.cross(&(x2 - x0));
    let n2 = (x3 - x0).cross(&e);
    let el = e.norm();
    if el == 0.0 {
        return 0.0;
    }
    let sin = n1.cross(&n2).dot(&e) / el;
    let cos = n1.dot(&n2);
    sin.atan2(cos)
}

/// Signed dihedral angles at every hinge of `topology`.
pub fn dihedral_angles(positions: &[Vector3<f64>], topology: &Topology) -> Vec<f64> {
    topology
        .hinges
        .iter()
        .map(|h| {
            let [x0, x1] = h.edge_vertices;
            dihedral_angle(
                &positions[x0],
                &positions[x1],
                &positions[h.opposite[0]],
                &positions[h.opposite[1]],
            )
        })
        .collect()
}

pub fn tet_volumes(positions: &[Vector3<f64>], tets: &[[usize; 4]]) -> Vec<f64> {
    tets.iter()
        .map(|t| tet_signed_volume(&positions[t[0]], &positions[t[1]], &positions[t[2]], &positions[t[3]]))
        .collect()
}

/// Shape matrix `D = [x1 − x0, x2 − x0, x3 − x0]` (columns) of a tetrahedron; the
/// deformation gradient is `F = D_s D_m⁻¹` (Sifakis & Barbič, FEM course notes §4).
pub fn tet_shape_matrix(positions: &[Vector3<f64>], t: &[usize; 4]) -> Matrix3<f64> {
    let x0 = positions[t[0]];
    Matrix3::from_columns(&[positions[t[1]] - x0, positions[t[2]] - x0, positions[t[3]] - x0])
}

/// Rest-shape inverses `D_m⁻¹` of every tet; fails on a degenerate one.
pub fn tet_rest_inverses(positions: &[Vector3<f64>], tets: &[[usize; 4]]) -> Result<Vec<Matrix3<f64>>> {
    tets.iter()
        .enumerate()
        .map(|(i, t)| {
            let d = tet_shape_matrix(positions, t);
            let volume = d.determinant() / 6.0;
            if !(volume > 0.0) {
                return Err(Error::BadTetVolume { tet: i, volume });
            }
            d.try_inverse().ok_or(Error::BadTetVolume { tet: i, volume })
        })
        .collect()
}

/// Lumped vertex masses of a volume mesh: each tet gives a quarter of `density · volume`
/// to each corner. `density` in kg/m³.
pub fn lumped_masses_tet(positions: &[Vector3<f64>], tets: &[[usize; 4]], density: f64) -> Vec<f64> {
    let mut m = vec![0.0; positions.len()];
    for (t, v) in tets.iter().zip(tet_volumes(positions, tets)) {
        for &i in t {
            m[i] += density * v.abs() / 4.0;
        }
    }
    m
}
