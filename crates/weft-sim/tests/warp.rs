//! NNWarp's geometric pieces (`weft_sim::warp`) on known answers: least-squares gradients
//! exact for affine fields, modal warping's closed form against quadrature, both warps
//! turning a linearised rigid rotation into the exact rotation, the alignment's rotation
//! invariance, and the contextual features' ranges and scale invariance.

use std::sync::Arc;

use nalgebra::{Matrix3, Rotation3, Vector3};
use weft_mesh::TetMesh;
use weft_mesh::generators::{BeamParams, beam};
use weft_sim::warp::{
    FieldDirection, NodalGradients, RotationStrainWarp, aligned_kinematics, contextual_features, modal_warp,
    modal_warp_matrix, rotation_vector, small_strain,
};
use weft_testkit::TestRng;

fn small_beam() -> TetMesh {
    beam(&BeamParams {
        cells: [6, 3, 3],
        size: [1.0, 0.5, 0.5],
    })
    .unwrap()
}

fn random_matrix(rng: &mut TestRng, scale: f64) -> Matrix3<f64> {
    Matrix3::from_fn(|_, _| rng.uniform(-scale, scale))
}

fn field(mesh: &TetMesh, f: impl Fn(&Vector3<f64>) -> Vector3<f64>) -> Vec<f64> {
    mesh.positions()
        .iter()
        .flat_map(|p| f(p).iter().copied().collect::<Vec<_>>())
        .collect()
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

#[test]
fn nodal_gradients_are_exact_for_affine_fields_at_every_node() {
    let mesh = small_beam();
    let grads = NodalGradients::new(&mesh).unwrap();
    let mut rng = TestRng::new(5);
    let a = random_matrix(&mut rng, 0.7);
    let b = Vector3::new(0.1, -0.3, 0.2);
    let u = field(&mesh, |p| a * p + b);
    for (i, g) in grads.gradients(&u).unwrap().iter().enumerate() {
        assert!((g - a).norm() < 1e-12, "node {i}: {g} vs {a}");
    }
    // G splits into its small strain and the rotation vector's cross matrix.
    let w = rotation_vector(&a);
    assert!((small_strain(&a) + w.cross_matrix() - a).norm() < 1e-14);
    let mut bad = u.clone();
    bad[7] = f64::NAN;
    assert!(grads.gradients(&bad).is_err());
    assert!(grads.gradients(&u[..6]).is_err());
}

#[test]
fn modal_warp_matrix_is_the_mean_of_the_rotation_along_the_path() {
    let mut rng = TestRng::new(8);
    for theta in [1e-7, 1e-5, 0.3, 1.7, 3.0] {
        let axis = Vector3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)).normalize();
        let w = axis * theta;
        // Composite Simpson over s ∈ [0, 1] of exp(s [w]×).
        let n = 400;
        let mut quad = Matrix3::zeros();
        for k in 0..=n {
            let s = k as f64 / n as f64;
            let c = if k == 0 || k == n {
                1.0
            } else if k % 2 == 1 {
                4.0
            } else {
                2.0
            };
            quad += c * Rotation3::from_scaled_axis(s * w).matrix();
        }
        quad /= 3.0 * n as f64;
        let closed = modal_warp_matrix(&w);
        assert!(
            (closed - quad).norm() < 1e-10,
            "θ = {theta}: {}",
            (closed - quad).norm()
        );
        // ∫₀¹ exp(s A) ds · A = exp(A) − I: warping a linearised rotation rotates exactly.
        let exact = Rotation3::from_scaled_axis(w).matrix() - Matrix3::identity();
        assert!((closed * w.cross_matrix() - exact).norm() < 1e-12);
    }
}

#[test]
fn both_warps_turn_a_linearised_rigid_rotation_into_the_rotation() {
    let mesh = small_beam();
    let grads = Arc::new(NodalGradients::new(&mesh).unwrap());
    // Anchor one node (the pivot); the linear solution of a rigid rotation by θ about it
    // is the infinitesimal one, ũ = [θ]× (x̄ − x̄_a).
    let pivot = 0;
    let xa = mesh.positions()[pivot];
    let theta = Vector3::new(0.2, -0.5, 0.6);
    let linear = field(&mesh, |p| theta.cross(&(p - xa)));
    let exact = field(&mesh, |p| Rotation3::from_scaled_axis(theta) * (p - xa) - (p - xa));
    let mw = modal_warp(&grads, &linear).unwrap();
    assert!(max_diff(&mw, &exact) < 1e-12, "MW: {}", max_diff(&mw, &exact));
    let mut anchored = vec![false; mesh.num_vertices()];
    anchored[pivot] = true;
    let rsw = RotationStrainWarp::new(&mesh, grads.clone(), anchored.clone()).unwrap();
    let got = rsw.warp(&linear).unwrap();
    assert!(max_diff(&got, &exact) < 1e-9, "RSW: {}", max_diff(&got, &exact));
    // A pure small strain has no rotation: RSW leaves it as it is, MW too.
    let s = Matrix3::new(0.05, 0.01, 0.0, 0.01, -0.02, 0.03, 0.0, 0.03, 0.04);
    let strain = field(&mesh, |p| s * (p - xa));
    assert!(max_diff(&rsw.warp(&strain).unwrap(), &strain) < 1e-9);
    assert!(max_diff(&modal_warp(&grads, &strain).unwrap(), &strain) < 1e-14);
    assert!(RotationStrainWarp::new(&mesh, grads, vec![false; mesh.num_vertices()]).is_err());
}

#[test]
fn alignment_takes_u_to_y_and_w_into_the_xy_plane_whatever_the_input_rotation() {
    let mut rng = TestRng::new(13);
    for _ in 0..50 {
        let v =
            |rng: &mut TestRng| Vector3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0));
        let (u, w) = (v(&mut rng), v(&mut rng));
        let (q, k) = aligned_kinematics(&u, &w);
        assert!((q * u - Vector3::new(0.0, u.norm(), 0.0)).norm() < 1e-12);
        let qw = q * w;
        assert!(qw.z.abs() < 1e-12 && qw.x <= 1e-12, "{qw}");
        assert!((Vector3::new(-k[2], k[1], 0.0) - qw).norm() < 1e-12);
        // Rotating the input rotates nothing the network sees, and the frames agree.
        let r = Rotation3::from_scaled_axis(v(&mut rng) * 2.0);
        let (qr, kr) = aligned_kinematics(&(r * u), &(r * w));
        for d in 0..3 {
            assert!((k[d] - kr[d]).abs() < 1e-12);
        }
        assert!((qr.matrix() * r.matrix() - q.matrix()).norm() < 1e-10);
    }
    // Degenerate inputs: ũ along −y, ũ = 0, w parallel to ũ.
    let (q, _) = aligned_kinematics(&Vector3::new(0.0, -2.0, 0.0), &Vector3::new(1.0, 0.0, 0.0));
    assert!((q * Vector3::new(0.0, -2.0, 0.0) - Vector3::new(0.0, 2.0, 0.0)).norm() < 1e-12);
    let (q, k) = aligned_kinematics(&Vector3::zeros(), &Vector3::new(0.0, 1.0, 0.0));
    assert_eq!(q, Rotation3::identity());
    assert_eq!(k, [0.0, 1.0, 0.0]);
    let (_, k) = aligned_kinematics(&Vector3::new(0.0, 0.0, 1.0), &Vector3::new(0.0, 0.0, 0.5));
    assert!((k[1] - 0.5).abs() < 1e-12 && k[2] < 1e-12);
}

#[test]
fn contextual_features_on_a_clamped_beam() {
    let mesh = small_beam();
    let anchors: Vec<usize> = (0..mesh.num_vertices())
        .filter(|&i| mesh.positions()[i].x.abs() < 1e-12)
        .collect();
    let x_max = mesh.positions().iter().map(|p| p.x).fold(0.0, f64::max);
    let along = contextual_features(&mesh, &anchors, FieldDirection::Directional(Vector3::x())).unwrap();
    for (i, f) in along.iter().enumerate() {
        let p = mesh.positions()[i];
        assert!((0.0..=1.0).contains(&f[0]) && (0.0..=1.0).contains(&f[1]));
        // Potential along +x is the rest position's x, normalised.
        assert!((f[1] - p.x / x_max).abs() < 1e-12);
        if anchors.contains(&i) {
            assert_eq!(f[0], 0.0);
            assert_eq!(f[2], 0.0);
        } else {
            // The nearest clamped node lies straight back along −x: digression 0.
            assert!(f[2].abs() < 1e-9, "node {i}: {}", f[2]);
        }
    }
    assert!(along.iter().any(|f| f[0] == 1.0));
    // Gravity (−y) across the beam: digression π/2 for nodes level with their anchor.
    let down = contextual_features(&mesh, &anchors, FieldDirection::Directional(-Vector3::y())).unwrap();
    for (i, f) in down.iter().enumerate() {
        assert!((0.0..=std::f64::consts::PI).contains(&f[2]));
        if !anchors.contains(&i) {
            assert!((f[2] - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        }
    }
    let circular = FieldDirection::Circular {
        center: Vector3::zeros(),
        axis: Vector3::x(),
    };
    let round = contextual_features(&mesh, &anchors, circular).unwrap();
    assert!(round.iter().all(|f| f[2] == -1.0 && (0.0..=1.0).contains(&f[1])));
    // Uniform scaling changes none of them.
    let scaled = TetMesh::new(mesh.positions().iter().map(|p| p * 3.0).collect(), mesh.tets().to_vec()).unwrap();
    let again = contextual_features(&scaled, &anchors, FieldDirection::Directional(Vector3::x())).unwrap();
    for (a, b) in along.iter().zip(&again) {
        for d in 0..3 {
            assert!((a[d] - b[d]).abs() < 1e-12);
        }
    }
    assert!(contextual_features(&mesh, &[], circular).is_err());
    assert!(contextual_features(&mesh, &anchors, FieldDirection::Directional(Vector3::zeros())).is_err());
}
