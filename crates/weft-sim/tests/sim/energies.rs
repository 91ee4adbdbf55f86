//! Every energy term: gradient vs central differences, Hessian vs differences of
//! gradients, zero at rest, invariance to rigid motion, PSD projection.

use std::sync::Arc;

use nalgebra::{Rotation3, Vector3};
use weft_linalg::{SymmetricMatrix, SymmetricPattern};
use weft_mesh::{Topology, TriMesh, generators};
use weft_sim::Energy;
use weft_sim::energies::*;
use weft_testkit::{TestRng, fd_directional, fd_gradient, max_norm_rel_error};

fn small_sheet() -> (TriMesh, Topology) {
    let m = generators::sheet(5, 0.4).unwrap();
    let t = Topology::new(&m);
    (m, t)
}

/// A random smooth-ish deformation of the rest state plus noise.
fn perturbed(x0: &[f64], rng: &mut TestRng, amount: f64) -> Vec<f64> {
    x0.iter().map(|v| v + rng.uniform(-amount, amount)).collect()
}

fn hessian_of(e: &dyn Energy, x: &[f64], project: bool) -> SymmetricMatrix {
    let mut pairs = Vec::new();
    e.hessian_pairs(&mut pairs);
    let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(x.len() / 3, pairs));
    let mut h = SymmetricMatrix::zeros(pattern);
    e.add_hessian(x, project, &mut h);
    h
}

fn gradient_of(e: &dyn Energy, x: &[f64]) -> Vec<f64> {
    let mut g = vec![0.0; x.len()];
    e.add_gradient(x, &mut g);
    g
}

/// Gradient vs central differences of the value, Hessian-vector products vs central
/// differences of the gradient, both to relative 1e-6 of the largest entry.
fn check_derivatives(e: &dyn Energy, x: &[f64], rng: &mut TestRng) {
    let g = gradient_of(e, x);
    let fd = fd_gradient(|y| e.value(y), x, 1e-6);
    let err = max_norm_rel_error(&g, &fd);
    assert!(err < 1e-6, "{}: gradient vs FD relative error {err:e}", e.name());
    let h = hessian_of(e, x, false);
    for _ in 0..3 {
        let v = rng.vec(x.len(), -1.0, 1.0);
        let mut hv = vec![0.0; x.len()];
        h.mul_vec(&v, &mut hv);
        let fd = fd_directional(|y| gradient_of(e, y), x, &v, 1e-6);
        let err = max_norm_rel_error(&hv, &fd);
        assert!(
            err < 1e-6,
            "{}: Hessian vs FD of gradient, relative error {err:e}",
            e.name()
        );
    }
}

/// Projected Hessians are PSD: the smallest eigenvalue of the assembled matrix (dense,
/// the test meshes are small) is non-negative up to round-off. Random quadratic forms
/// would miss a single negative direction.
fn check_projected_psd(e: &dyn Energy, x: &[f64], _rng: &mut TestRng) {
    let h = hessian_of(e, x, true);
    let n = x.len();
    let dense = nalgebra::DMatrix::from_fn(n, n, |r, c| h.get(r, c));
    let eig = dense.symmetric_eigenvalues();
    let max = eig.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
    let min = eig.iter().fold(f64::INFINITY, |m, v| m.min(*v));
    assert!(
        min >= -1e-10 * max,
        "{}: projected Hessian has eigenvalue {min:e} (largest |λ| {max:e})",
        e.name()
    );
    // The check has teeth: the unprojected Hessian of a compressed configuration is not PSD
    // for every term here (see `unprojected_hessians_of_compressed_states_are_indefinite`).
}

fn rigidly_moved(x: &[f64], r: &Rotation3<f64>, t: Vector3<f64>) -> Vec<f64> {
    x.chunks(3)
        .flat_map(|p| {
            let q = r * Vector3::new(p[0], p[1], p[2]) + t;
            [q.x, q.y, q.z]
        })
        .collect()
}

fn cloth_energies(m: &TriMesh, t: &Topology) -> Vec<Box<dyn Energy>> {
    vec![
        Box::new(Springs::stretch(m, t, 300.0).unwrap()),
        Box::new(Springs::bend_two_ring(m, t, 7.0).unwrap()),
        Box::new(Membrane::new(m, 500.0, 0.3).unwrap()),
        Box::new(DihedralBending::new(m, t, 0.02).unwrap()),
    ]
}

#[test]
fn cloth_energy_derivatives_match_finite_differences() {
    let (m, t) = small_sheet();
    let mut rng = TestRng::new(11);
    let x0 = m.flat_positions();
    for e in cloth_energies(&m, &t) {
        for amount in [0.01, 0.05] {
            let x = perturbed(&x0, &mut rng, amount);
            check_derivatives(e.as_ref(), &x, &mut rng);
            check_projected_psd(e.as_ref(), &x, &mut rng);
        }
    }
}

#[test]
fn dihedral_bending_derivatives_on_a_curved_rest_shape() {
    // Non-flat rest angles (a ball) exercise θ̄ ≠ 0 and the angle wrap.
    let m = generators::ball(8, 5, 0.3).unwrap();
    let t = Topology::new(&m);
    let e = DihedralBending::new(&m, &t, 0.05).unwrap();
    let mut rng = TestRng::new(5);
    let x = perturbed(&m.flat_positions(), &mut rng, 0.02);
    check_derivatives(&e, &x, &mut rng);
}

#[test]
fn cloth_energies_vanish_at_rest_and_under_rigid_motion() {
    let (m, t) = small_sheet();
    let x0 = m.flat_positions();
    let r = Rotation3::from_euler_angles(0.7, -1.2, 2.9);
    let moved = rigidly_moved(&x0, &r, Vector3::new(0.3, -2.0, 5.0));
    let mut rng = TestRng::new(3);
    let deformed = perturbed(&x0, &mut rng, 0.03);
    let deformed_moved = rigidly_moved(&deformed, &r, Vector3::new(0.3, -2.0, 5.0));
    for e in cloth_energies(&m, &t) {
        assert!(e.value(&x0).abs() < 1e-20, "{} not zero at rest", e.name());
        assert!(
            e.value(&moved).abs() < 1e-12,
            "{} not zero after rigid motion: {}",
            e.name(),
            e.value(&moved)
        );
        assert!(
            gradient_of(e.as_ref(), &x0).iter().all(|g| g.abs() < 1e-12),
            "{} has force at rest",
            e.name()
        );
        let (a, b) = (e.value(&deformed), e.value(&deformed_moved));
        assert!(
            a > 0.0 && (a - b).abs() <= 1e-9 * a,
            "{}: {a} vs {b} after rigid motion",
            e.name()
        );
    }
}

#[test]
fn membrane_matches_the_analytic_uniaxial_stretch_energy() {
    // Stretch a unit square by s along X: E_xx = (s² − 1)/2, others 0;
    // Ψ = μ E_xx² + ½ λ E_xx², total = area · Ψ.
    let m = generators::sheet(3, 1.0).unwrap();
    let (y, nu) = (1000.0, 0.25);
    let e = Membrane::new(&m, y, nu).unwrap();
    let s: f64 = 1.1;
    let x: Vec<f64> = m.positions().iter().flat_map(|p| [s * p.x, p.y, p.z]).collect();
    let exx = 0.5 * (s * s - 1.0);
    let mu = y / (2.0 * (1.0 + nu));
    let lambda = y * nu / (1.0 - nu * nu);
    weft_testkit::assert_close!(e.value(&x), (mu + 0.5 * lambda) * exx * exx, rtol = 1e-12, atol = 0.0);
}

#[test]
fn dihedral_bending_matches_the_analytic_hinge_energy() {
    let m = TriMesh::new(
        vec![
            Vector3::new(0., 0., 0.),
            Vector3::new(1., 0., 0.),
            Vector3::new(0.5, 1., 0.),
            Vector3::new(0.5, -1., 0.),
        ],
        vec![[0, 1, 2], [1, 0, 3]],
    )
    .unwrap();
    let t = Topology::new(&m);
    let e = DihedralBending::new(&m, &t, 2.0).unwrap();
    // Fold the second triangle by θ about the X axis.
    let theta: f64 = 0.4;
    let mut x = m.flat_positions();
    x[3 * 3 + 1] = -theta.cos();
    x[3 * 3 + 2] = theta.sin();
    // k θ² |e|² / ((A1 + A2)/3) with |e| = 1, A = 0.5 each.
    weft_testkit::assert_close!(
        e.value(&x),
        2.0 * theta * theta * 1.0 / (1.0 / 3.0),
        rtol = 1e-12,
        atol = 0.0
    );
}

#[test]
fn obstacle_derivatives_and_zero_outside() {
    let mut rng = TestRng::new(9);
    // Points scattered around and inside each obstacle's margin.
    let n = 30;
    let sphere = ObstaclePenalty::new(
        ObstacleShape::Sphere {
            center: Vector3::new(0.1, 0.0, -0.2),
            radius: 0.3,
        },
        n,
        1e3,
        0.05,
    )
    .unwrap();
    let plane = ObstaclePenalty::new(
        ObstacleShape::Plane {
            point: Vector3::zeros(),
            normal: Vector3::new(0.2, 0.1, 1.0),
        },
        n,
        1e3,
        0.05,
    )
    .unwrap();
    // A closed box obstacle, tested at points over its faces' interiors (flat features).
    let boxmesh = generators::beam(&generators::BeamParams {
        cells: [1, 1, 1],
        size: [1.0, 1.0, 1.0],
    })
    .unwrap()
    .boundary_surface()
    .unwrap()
    .mesh;
    let cube = ObstaclePenalty::new(ObstacleShape::mesh(&boxmesh).unwrap(), n, 1e3, 0.05).unwrap();
    let around_sphere: Vec<f64> = (0..n)
        .flat_map(|_| {
            let d = Vector3::new(rng.uniform(-1., 1.), rng.uniform(-1., 1.), rng.uniform(-1., 1.)).normalize();
            let p = Vector3::new(0.1, 0.0, -0.2) + d * rng.uniform(0.2, 0.4);
            [p.x, p.y, p.z]
        })
        .collect();
    let around_plane: Vec<f64> = (0..n)
        .flat_map(|_| [rng.uniform(-1., 1.), rng.uniform(-1., 1.), rng.uniform(-0.1, 0.1)])
        .collect();
    let above_cube_top: Vec<f64> = (0..n)
        .flat_map(|_| [rng.uniform(0.2, 0.8), rng.uniform(0.2, 0.8), rng.uniform(0.97, 1.04)])
        .collect();
    for (e, x) in [
        (&sphere, &around_sphere),
        (&plane, &around_plane),
        (&cube, &above_cube_top),
    ] {
        assert!(e.value(x) > 0.0, "some points must be in contact");
        check_derivatives(e, x, &mut rng);
        check_projected_psd(e, x, &mut rng);
    }
    // Far away: no energy, no force.
    let far = vec![5.0; 3 * n];
    for e in [&sphere, &plane, &cube] {
        assert_eq!(e.value(&far), 0.0);
        assert!(gradient_of(e, &far).iter().all(|&g| g == 0.0));
    }
    // Inside the box (deep) is inside: large penalty pushing out through the nearest face.
    let inside = [0.5, 0.5, 0.9].repeat(n);
    let g = gradient_of(&cube, &inside);
    assert!(
        g[2] < 0.0,
        "descent direction −∇E must point out through the top face (+Z)"
    );
}

#[test]
fn inertia_and_gravity_derivatives() {
    let mut rng = TestRng::new(2);
    let x0 = rng.vec(12, -1.0, 1.0);
    let mut inertia = Inertia::new(vec![0.1, 0.2, 0.3, 0.4], 0.01, &x0).unwrap();
    let prev = rng.vec(12, -1.0, 1.0);
    inertia.set_history(&x0, &prev).unwrap();
    let x = rng.vec(12, -1.0, 1.0);
    check_derivatives(&inertia, &x, &mut rng);
    let gravity = ConstantForce::gravity(&[0.1, 0.2, 0.3, 0.4], [0.0, 0.0, -9.81]).unwrap();
    check_derivatives(&gravity, &x, &mut rng);
    // Gravity's potential is m g h.
    let lifted: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(i, v)| if i % 3 == 2 { v + 1.0 } else { *v })
        .collect();
    weft_testkit::assert_close!(
        gravity.value(&lifted) - gravity.value(&x),
        9.81,
        rtol = 1e-12,
        atol = 0.0
    );
}

#[test]
fn stiffness_scaling_scales_energy() {
    let (m, t) = small_sheet();
    let mut rng = TestRng::new(4);
    let x = perturbed(&m.flat_positions(), &mut rng, 0.03);
    let mut s = Springs::stretch(&m, &t, 100.0).unwrap();
    let mut memb = Membrane::new(&m, 100.0, 0.3).unwrap();
    let mut bend = DihedralBending::new(&m, &t, 1.0).unwrap();
    let before = [s.value(&x), memb.value(&x), bend.value(&x)];
    s.scale_stiffness(0.1);
    memb.scale_stiffness(0.1);
    bend.scale_stiffness(0.1);
    let after = [s.value(&x), memb.value(&x), bend.value(&x)];
    for (b, a) in before.iter().zip(after) {
        weft_testkit::assert_close!(a, 0.1 * b, rtol = 1e-12, atol = 0.0);
    }
}

#[test]
fn bad_parameters_are_typed_errors() {
    let (m, t) = small_sheet();
    assert!(Membrane::new(&m, 100.0, 0.5).is_err());
    assert!(Membrane::new(&m, f64::NAN, 0.3).is_err());
    assert!(Springs::stretch(&m, &t, -1.0).is_err());
    assert!(DihedralBending::new(&m, &t, f64::INFINITY).is_err());
    assert!(
        ObstaclePenalty::new(
            ObstacleShape::Sphere {
                center: Vector3::zeros(),
                radius: 0.0
            },
            3,
            1.0,
            0.0
        )
        .is_err()
    );
    assert!(Inertia::new(vec![1.0], 0.0, &[0.0; 3]).is_err());
    assert!(ConstantForce::new("f", vec![f64::NAN]).is_err());
}

#[test]
fn collapsed_hinge_triangles_and_edges_give_finite_bending_gradients_and_hessians() {
    // Regression: the closed-form dihedral gradient divided by |n_A|² and |e|² unguarded,
    // so a collapsed triangle (crumpling cloth reaches one) gave a finite energy but a NaN
    // gradient and Hessian, and the Newton step died.
    let m = generators::sheet(2, 1.0).unwrap(); // two triangles, one hinge
    let t = Topology::new(&m);
    let bend = DihedralBending::new(&m, &t, 1.0).unwrap();
    let x0 = m.flat_positions();
    let [a, b] = t.hinges[0].edge_vertices;
    let [c, _] = t.hinges[0].opposite;
    let mid = |x: &[f64], i: usize, j: usize| -> [f64; 3] { [0, 1, 2].map(|k| 0.5 * (x[3 * i + k] + x[3 * j + k])) };
    // Opposite vertex moved onto the hinge edge: that triangle has zero area.
    let mut flat_triangle = x0.clone();
    flat_triangle[3 * c..3 * c + 3].copy_from_slice(&mid(&x0, a, b));
    // Hinge edge collapsed to a point.
    let mut collapsed_edge = x0.clone();
    let p = mid(&x0, a, b);
    collapsed_edge[3 * a..3 * a + 3].copy_from_slice(&p);
    collapsed_edge[3 * b..3 * b + 3].copy_from_slice(&p);
    for x in [&flat_triangle, &collapsed_edge] {
        assert!(bend.value(x).is_finite());
        assert!(gradient_of(&bend, x).iter().all(|g| g.is_finite()));
        for project in [false, true] {
            let h = hessian_of(&bend, x, project);
            assert!(h.values().iter().all(|v| v.is_finite()), "project {project}");
        }
    }
    // Away from degeneracy the guard is invisible: a bent hinge still matches differences.
    let mut bent = x0.clone();
    bent[3 * c + 2] += 0.1;
    let g = gradient_of(&bend, &bent);
    let fd = fd_gradient(|x| bend.value(x), &bent, 1e-6);
    assert!(max_norm_rel_error(&g, &fd) < 1e-6);
}

#[test]
fn unprojected_hessians_of_compressed_states_are_indefinite() {
    // Guards the PSD check above: with projection off, compressed springs and membranes
    // have negative eigenvalues, and the eigenvalue test finds them.
    let (m, t) = small_sheet();
    let x: Vec<f64> = m.flat_positions().iter().map(|v| 0.7 * v).collect();
    for e in [
        Box::new(Springs::stretch(&m, &t, 10.0).unwrap()) as Box<dyn Energy>,
        Box::new(Membrane::new(&m, 100.0, 0.3).unwrap()),
    ] {
        let h = hessian_of(e.as_ref(), &x, false);
        let n = x.len();
        let dense = nalgebra::DMatrix::from_fn(n, n, |r, c| h.get(r, c));
        let min = dense
            .symmetric_eigenvalues()
            .iter()
            .fold(f64::INFINITY, |m, v| m.min(*v));
        assert!(
            min < 0.0,
            "{}: expected an indefinite Hessian, min eigenvalue {min:e}",
            e.name()
        );
    }
}
