//! The drape scene: the kinematic guess's binding, its rigid invariance, and the draped
//! equilibrium (converged, sewn ring held, outside the body, sagging under gravity).

use nalgebra::{Rotation3, Vector3};
use weft_sim::rng::SplitMix64;
use weft_sim::scenes::drape::{Drape, DrapeParams};
use weft_sim::scenes::soft_tissue::ArmPose;

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

#[test]
fn the_kinematic_guess_at_the_neutral_pose_is_the_rest_sleeve() {
    let d = Drape::new(DrapeParams::quick()).unwrap();
    let guess = d.kinematic_guess(&ArmPose::default());
    assert!(max_diff(&guess, &d.sleeve().flat_positions()) < 1e-12);
}

#[test]
fn with_a_straight_elbow_the_guess_moves_rigidly_with_the_shoulder() {
    // Elbow flexion 0: both bones share one rigid transform, so the skinned body and the
    // sleeve bound to it rotate rigidly about the shoulder.
    let d = Drape::new(DrapeParams::quick()).unwrap();
    let pose = ArmPose {
        shoulder_flexion: 0.3,
        shoulder_abduction: -0.4,
        elbow_flexion: 0.0,
        bounce: 0.0,
    };
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), -0.4) * Rotation3::from_axis_angle(&Vector3::y_axis(), 0.3);
    let expected: Vec<f64> = d.sleeve().positions().iter().flat_map(|p| (r * p).data.0[0]).collect();
    assert!(max_diff(&d.kinematic_guess(&pose), &expected) < 1e-12);
}

#[test]
fn the_draped_sleeve_is_an_equilibrium_outside_the_body_that_sags() {
    let params = DrapeParams::quick();
    let d = Drape::new(params).unwrap();
    let mut rng = SplitMix64::new(7);
    // Some poses do not converge within the iteration limit (the dataset replaces them and
    // records them); most must.
    let solved: Vec<_> = (0..4)
        .filter_map(|_| d.solve(&ArmPose::sample(&mut rng)).ok())
        .collect();
    assert!(solved.len() >= 3, "only {} of 4 poses converged", solved.len());
    for e in solved {
        let pose = e.pose;
        assert!(e.report.residual <= e.report.initial_residual);
        // The sewn ring stays on the guess.
        for &v in d.sewn() {
            assert!(max_diff(&e.truth[3 * v..3 * v + 3], &e.guess[3 * v..3 * v + 3]) == 0.0);
        }
        // Every vertex is outside the posed body (penetration below 0.1 mm).
        let body = d.body(&pose).unwrap();
        let obstacle = weft_sim::energies::ObstaclePenalty::new(
            weft_sim::energies::ObstacleShape::mesh(&body).unwrap(),
            e.truth.len() / 3,
            1.0,
            0.0,
        )
        .unwrap();
        for x in e.truth.chunks(3) {
            let d = obstacle.signed_distance(&Vector3::new(x[0], x[1], x[2]));
            assert!(d > -1e-4, "vertex {x:?} is {d} m inside the body");
        }
        // Gravity pulls the sleeve down: its mean height drops by millimetres.
        let n = e.truth.len() / 3;
        let dz: f64 = (0..n).map(|v| e.truth[3 * v + 2] - e.guess[3 * v + 2]).sum::<f64>() / n as f64;
        assert!(dz < -1e-3, "mean vertical displacement {dz} m");
    }
}

#[test]
fn a_sleeve_off_the_arm_is_a_typed_error() {
    let mut p = DrapeParams::quick();
    p.sleeve_end = 0.9;
    let e = Drape::new(p).unwrap_err().to_string();
    assert!(e.contains("sleeve"), "{e}");
    let mut p = DrapeParams::quick();
    p.offset = -0.01;
    assert!(Drape::new(p).is_err());
}
