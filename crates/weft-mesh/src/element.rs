//! Per-element formulas and the edge list of a face list: what validating a mesh needs
//! ([`TriMesh`](crate::TriMesh) checks face areas and counts edges, [`TetMesh`](crate::TetMesh)
//! checks orientations), kept below the mesh types so they import nothing above them.
//! [`geometry`](crate::geometry) and [`topology`](crate::topology) re-export these; this
//! module is not the place for anything a mesh type does not itself need.

use nalgebra::Vector3;

/// Area of triangle `abc`.
pub fn triangle_area(a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>) -> f64 {
    0.5 * (b - a).cross(&(c - a)).norm()
}

/// Areas of every face.
pub fn face_areas(positions: &[Vector3<f64>], faces: &[[usize; 3]]) -> Vec<f64> {
    faces
        .iter()
        .map(|f| triangle_area(&positions[f[0]], &positions[f[1]], &positions[f[2]]))
        .collect()
}

/// Signed volume of tetrahedron `abcd`: `det[b − a, c − a, d − a] / 6`.
pub fn tet_signed_volume(a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>, d: &Vector3<f64>) -> f64 {
    (b - a).cross(&(c - a)).dot(&(d - a)) / 6.0
}

/// Unique sorted edges of a face list.
pub fn unique_edges(faces: &[[usize; 3]]) -> Vec<[usize; 2]> {
    let mut edges: Vec<[usize; 2]> = faces
        .iter()
        .flat_map(|f| (0..3).map(move |k| sorted2(f[k], f[(k + 1) % 3])))
        .collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// The edge `{a, b}` as `[min, max]`.
pub(crate) fn sorted2(a: usize, b: usize) -> [usize; 2] {
    if a < b { [a, b] } else { [b, a] }
}
