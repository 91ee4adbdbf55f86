//! Choosing Dirichlet (anchor) nodes: by a plane, at the minimum of a coordinate, or by
//! an index list — and turning node lists into the per-DOF masks the solvers take.

use nalgebra::Vector3;

use crate::error::{Error, Result};

/// Nodes within `tolerance` (m) of the plane through `point` with normal `normal`.
pub fn nodes_on_plane(
    positions: &[Vector3<f64>],
    point: [f64; 3],
    normal: [f64; 3],
    tolerance: f64,
) -> Result<Vec<usize>> {
    let n = Vector3::from(normal);
    let len = n.norm();
    if !(len.is_finite() && len > 0.0) {
        return Err(Error::InvalidParameter {
            name: "anchor plane normal",
            value: len,
            reason: "must be non-zero",
        });
    }
    if !(tolerance.is_finite() && tolerance >= 0.0) {
        return Err(Error::InvalidParameter {
            name: "anchor plane tolerance",
            value: tolerance,
            reason: "must be non-negative and finite",
        });
    }
    let (n, p) = (n / len, Vector3::from(point));
    Ok((0..positions.len())
        .filter(|&i| (positions[i] - p).dot(&n).abs() <= tolerance)
        .collect())
}

/// Nodes whose coordinate `axis` (0 = x, 1 = y, 2 = z) is within `tolerance` (m) of its
/// minimum over the mesh — "every node at minimum x" for `axis = 0`.
pub fn nodes_at_min(positions: &[Vector3<f64>], axis: usize, tolerance: f64) -> Result<Vec<usize>> {
    if axis > 2 {
        return Err(Error::InvalidParameter {
            name: "anchor axis",
            value: axis as f64,
            reason: "must be 0, 1 or 2",
        });
    }
    let min = positions.iter().map(|p| p[axis]).fold(f64::INFINITY, f64::min);
    let mut point = [0.0; 3];
    point[axis] = min;
    let mut normal = [0.0; 3];
    normal[axis] = 1.0;
    nodes_on_plane(positions, point, normal, tolerance)
}

/// The per-DOF fixed mask (3 DOFs per node) of `nodes` over `num_vertices` nodes; fails
/// on an index out of range.
pub fn fixed_dofs(num_vertices: usize, nodes: &[usize]) -> Result<Vec<bool>> {
    let mut fixed = vec![false; 3 * num_vertices];
    for &v in nodes {
        if v >= num_vertices {
            return Err(Error::VertexOutOfRange {
                what: "anchor list",
                index: v,
                num_vertices,
            });
        }
        fixed[3 * v..3 * v + 3].iter_mut().for_each(|f| *f = true);
    }
    Ok(fixed)
}

/// `(dof, value)` pairs holding every DOF of `nodes` at its value in `x` — the
/// `prescribed` argument of the integrators for anchors that stay put.
pub fn hold(nodes: &[usize], x: &[f64]) -> Vec<(usize, f64)> {
    nodes
        .iter()
        .flat_map(|&v| (3 * v..3 * v + 3).map(|d| (d, x[d])))
        .collect()
}

/// Checks integrator input: every prescribed DOF exists, is in the `fixed` mask, and has a
/// finite value.
pub fn check_prescribed(prescribed: &[(usize, f64)], fixed: &[bool]) -> Result<()> {
    for &(dof, value) in prescribed {
        if dof >= fixed.len() || !fixed[dof] {
            return Err(Error::Scene(format!(
                "DOF {dof} is prescribed but not in the fixed set"
            )));
        }
        if !value.is_finite() {
            return Err(Error::NonFinite {
                what: "prescribed position",
                dof,
            });
        }
    }
    Ok(())
}

/// How many of the six rigid motions of the body at `rest` (flat, m) the `fixed` DOFs
/// leave free. A static solve `K u = f` is singular unless this is 0; relying on Cholesky
/// to reject a singular `K` is unsafe, since round-off can leave a tiny positive pivot.
///
/// The rigid motions at DOF `(v, k)` are the translations `e_j` and the rotations
/// `(e_j × (x_v − c))/L` about the centroid `c` (scaled by the body size `L` so all six
/// are of order one). The fixed DOFs remove exactly as many motions as the rank of the
/// 6 × 6 Gram matrix of their rows; eigenvalues below `10⁻¹⁰` of the largest count as
/// zero.
pub fn free_rigid_modes(rest: &[f64], fixed: &[bool]) -> usize {
    let n = rest.len() / 3;
    if n == 0 {
        return 6;
    }
    let node = |v: usize| Vector3::new(rest[3 * v], rest[3 * v + 1], rest[3 * v + 2]);
    let c = (0..n).map(node).sum::<Vector3<f64>>() / n as f64;
    let size = (0..n)
        .map(|v| (node(v) - c).norm())
        .fold(0.0f64, f64::max)
        .max(f64::MIN_POSITIVE);
    let mut gram = nalgebra::Matrix6::<f64>::zeros();
    for (dof, _) in fixed.iter().enumerate().filter(|(_, f)| **f) {
        let (v, k) = (dof / 3, dof % 3);
        let d = (node(v) - c) / size;
        let mut row = nalgebra::Vector6::<f64>::zeros();
        row[k] = 1.0;
        for j in 0..3 {
            row[3 + j] = Vector3::ith(j, 1.0).cross(&d)[k];
        }
        gram += row * row.transpose();
    }
    let eig = gram.symmetric_eigenvalues();
    let max = eig.iter().fold(0.0f64, |m, e| m.max(*e));
    eig.iter().filter(|&&e| e <= 1e-10 * max.max(f64::MIN_POSITIVE)).count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rigid_modes_left_free_by_one_two_and_three_anchors() {
        // Four nodes of a unit tetrahedron.
        let rest = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let mask = |nodes: &[usize]| fixed_dofs(4, nodes).unwrap();
        assert_eq!(free_rigid_modes(&rest, &mask(&[])), 6);
        assert_eq!(free_rigid_modes(&rest, &mask(&[0])), 3); // rotations about the node
        assert_eq!(free_rigid_modes(&rest, &mask(&[0, 1])), 1); // rotation about their line
        assert_eq!(free_rigid_modes(&rest, &mask(&[0, 1, 2])), 0);
        // Partial masks: every x and y DOF fixed leaves translation along z free.
        let xy: Vec<bool> = (0..12).map(|d| d % 3 != 2).collect();
        assert_eq!(free_rigid_modes(&rest, &xy), 1);
    }
}
