//! Analytic smooth deformations of the built-in meshes, shared by the integration tests
//! and the round-trip measurements in docs/ACAP.md.
#![allow(dead_code)]

use nalgebra::{Matrix3, Rotation3, Unit, Vector3};
use std::f64::consts::PI;
use weft_mesh::{TriMesh, generators};

pub fn sheet(n: usize) -> TriMesh {
    generators::sheet(n, 1.0).expect("valid sheet")
}

pub fn ball() -> TriMesh {
    generators::ball(48, 32, 0.5).expect("valid ball")
}

/// The two corners at y = −0.5 of an `n × n` sheet: Tan et al.'s grasp points.
pub fn sheet_grasp_corners(n: usize) -> Vec<usize> {
    vec![0, n - 1]
}

/// The poles of the ball.
pub fn ball_poles(mesh: &TriMesh) -> Vec<usize> {
    vec![0, mesh.num_vertices() - 1]
}

fn map(mesh: &TriMesh, f: impl Fn(&Vector3<f64>) -> Vector3<f64>) -> Vec<Vector3<f64>> {
    mesh.positions().iter().map(f).collect()
}

/// Bends the sheet about an axis parallel to Y into a cylinder arc of `radius`
/// (isometric); the arc spans `1 / radius` radians.
pub fn cylinder_arc(mesh: &TriMesh, radius: f64) -> Vec<Vector3<f64>> {
    map(mesh, |q| {
        Vector3::new(
            radius * (q.x / radius).sin(),
            q.y,
            radius * (1.0 - (q.x / radius).cos()),
        )
    })
}

/// Folds the sheet by 180° about the line x = 0: flat for x < −a, a half-cylinder of
/// radius 2a/π over −a ≤ x ≤ a, folded back flat above for x > a (isometric). The folded
/// half is rotated by exactly π.
pub fn fold(mesh: &TriMesh, half_width: f64) -> Vec<Vector3<f64>> {
    let a = half_width;
    let rho = 2.0 * a / PI;
    map(mesh, |q| {
        if q.x < -a {
            Vector3::new(q.x, q.y, 0.0)
        } else if q.x <= a {
            let alpha = PI * (q.x + a) / (2.0 * a);
            Vector3::new(-a + rho * alpha.sin(), q.y, rho * (1.0 - alpha.cos()))
        } else {
            Vector3::new(-a - (q.x - a), q.y, 2.0 * rho)
        }
    })
}

/// Twists the sheet about the X axis, the angle growing linearly from 0 at x = −0.5 to
/// `total` at x = +0.5.
pub fn twist_sheet(mesh: &TriMesh, total: f64) -> Vec<Vector3<f64>> {
    map(mesh, |q| {
        let a = total * (q.x + 0.5);
        Vector3::new(q.x, q.y * a.cos(), q.y * a.sin())
    })
}

/// Gravity-like sag from the pinned edge y = −0.5: z = −c (y + 0.5)².
pub fn sag(mesh: &TriMesh, c: f64) -> Vec<Vector3<f64>> {
    map(mesh, |q| Vector3::new(q.x, q.y, -c * (q.y + 0.5).powi(2)))
}

/// Stretches the ball along Z by `stretch` (volume-preserving in X, Y) and twists it
/// about Z by `total_twist` from pole to pole.
pub fn pull_and_twist_ball(mesh: &TriMesh, stretch: f64, total_twist: f64) -> Vec<Vector3<f64>> {
    let r = 0.5;
    let lateral = 1.0 / stretch.sqrt();
    map(mesh, |q| {
        let a = total_twist * q.z / (2.0 * r);
        let (s, c) = a.sin_cos();
        let (x, y) = (lateral * q.x, lateral * q.y);
        Vector3::new(c * x - s * y, s * x + c * y, stretch * q.z)
    })
}

/// A rigid motion: rotation by `angle` about `axis`, then translation.
pub fn rigid(mesh: &TriMesh, axis: Vector3<f64>, angle: f64, translation: Vector3<f64>) -> Vec<Vector3<f64>> {
    let rot = rigid_rotation(axis, angle);
    map(mesh, |q| rot * q + translation)
}

pub fn rigid_rotation(axis: Vector3<f64>, angle: f64) -> Matrix3<f64> {
    Rotation3::from_axis_angle(&Unit::new_normalize(axis), angle).into_inner()
}

/// Named deformation cases of the round-trip table in docs/ACAP.md: (name, rest mesh,
/// deformed positions, pins).
pub fn round_trip_cases(n: usize) -> Vec<(&'static str, TriMesh, Vec<Vector3<f64>>, Vec<usize>)> {
    let s = sheet(n);
    let b = ball();
    let corners = sheet_grasp_corners(n);
    let poles = ball_poles(&b);
    vec![
        (
            "sheet cylinder arc, 229°",
            s.clone(),
            cylinder_arc(&s, 0.25),
            corners.clone(),
        ),
        ("sheet fold 180°", s.clone(), fold(&s, 0.1), corners.clone()),
        (
            "sheet twist 200°",
            s.clone(),
            twist_sheet(&s, 200f64.to_radians()),
            corners.clone(),
        ),
        ("sheet sag", s.clone(), sag(&s, 0.6), corners.clone()),
        (
            "ball pulled 1.5× and twisted 200°",
            b.clone(),
            pull_and_twist_ball(&b, 1.5, 200f64.to_radians()),
            poles,
        ),
    ]
}
