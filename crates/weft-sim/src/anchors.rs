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
