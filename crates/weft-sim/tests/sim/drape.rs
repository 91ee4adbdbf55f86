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
        shoulder_twist: 0.9,
        ..ArmPose::default()
    };
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), -0.4)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), 0.3)
        * Rotation3::from_axis_angle(&Vector3::x_axis(), 0.9);
    let expected: Vec<f64> = d.sleeve().positions().iter().flat_map(|p| (r * p).data.0[0]).collect();
    assert!(max_diff(&d.kinematic_guess(&pose), &expected) < 1e-12);
}

/// Solves four poses of stream 7 (at least three must converge; the dataset replaces and
/// records the others) and checks each: the residual fell, the sewn ring stayed on the
/// guess, no vertex is inside the posed body (below 0.1 mm), and the mean height dropped by
/// more than `drop` m under gravity.
fn assert_drapes(params: DrapeParams, drop: f64) -> Vec<weft_sim::scenes::drape::DrapeExample> {
    let d = Drape::new(params).unwrap();
    let mut rng = SplitMix64::new(7);
    let solved: Vec<_> = (0..4).filter_map(|_| d.solve(&d.sample_pose(&mut rng)).ok()).collect();
    assert!(solved.len() >= 3, "only {} of 4 poses converged", solved.len());
    for e in &solved {
        assert!(e.report.residual <= e.report.initial_residual);
        for &v in d.sewn() {
            assert!(max_diff(&e.truth[3 * v..3 * v + 3], &e.guess[3 * v..3 * v + 3]) == 0.0);
        }
        let body = d.body(&e.pose).unwrap();
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
        let n = e.truth.len() / 3;
        let dz: f64 = (0..n).map(|v| e.truth[3 * v + 2] - e.guess[3 * v + 2]).sum::<f64>() / n as f64;
        assert!(dz < -drop, "mean vertical displacement {dz} m");
    }
    solved
}

#[test]
fn the_draped_sleeve_is_an_equilibrium_outside_the_body_that_sags() {
    // Gravity pulls the sleeve down: its mean height drops by millimetres.
    let solved = assert_drapes(DrapeParams::quick(), 1e-3);
    assert!(solved.iter().all(|e| e.settle_iterations == 0));
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

#[test]
fn the_loose_sleeves_guess_at_the_neutral_pose_is_the_rest_sleeve() {
    for params in [DrapeParams::loose_quick(), DrapeParams::loose()] {
        let d = Drape::new(params).unwrap();
        let guess = d.kinematic_guess(&ArmPose::default());
        assert!(max_diff(&guess, &d.sleeve().flat_positions()) < 1e-12);
    }
}

#[test]
fn with_a_straight_elbow_the_skinned_guess_moves_rigidly_with_the_shoulder() {
    let d = Drape::new(DrapeParams::loose_quick()).unwrap();
    let pose = ArmPose {
        shoulder_flexion: -0.2,
        shoulder_abduction: 0.35,
        shoulder_twist: -1.2,
        ..ArmPose::default()
    };
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.35)
        * Rotation3::from_axis_angle(&Vector3::y_axis(), -0.2)
        * Rotation3::from_axis_angle(&Vector3::x_axis(), -1.2);
    let expected: Vec<f64> = d.sleeve().positions().iter().flat_map(|p| (r * p).data.0[0]).collect();
    assert!(max_diff(&d.kinematic_guess(&pose), &expected) < 1e-12);
}

#[test]
fn the_loose_sleeves_poses_stay_in_its_ranges_and_the_sleeves_draws_are_unchanged() {
    let loose = Drape::new(DrapeParams::loose_quick()).unwrap();
    let sleeve = Drape::new(DrapeParams::quick()).unwrap();
    let params = DrapeParams::loose();
    let ([lo, hi], s, t) = (params.elbow_flexion, params.shoulder_range, params.twist_range);
    let mut a = SplitMix64::new(3);
    let (mut widest, mut widest_twist) = (0.0f64, 0.0f64);
    for _ in 0..200 {
        let p = loose.sample_pose(&mut a);
        assert!((lo..=hi).contains(&p.elbow_flexion), "{p:?}");
        assert!(
            p.shoulder_flexion.abs() <= s && p.shoulder_abduction.abs() <= s && p.shoulder_twist.abs() <= t,
            "{p:?}"
        );
        widest = widest.max(p.shoulder_flexion.abs());
        widest_twist = widest_twist.max(p.shoulder_twist.abs());
    }
    assert!(widest > 0.9 * s, "the draws span the range: widest flexion {widest}");
    assert!(
        widest_twist > 0.9 * t,
        "the draws span the range: widest twist {widest_twist}"
    );
    // The sleeve's scene draws exactly as `ArmPose::sample` (its dataset stays as it was).
    let (mut a, mut b2) = (SplitMix64::new(9), SplitMix64::new(9));
    for _ in 0..50 {
        let p = sleeve.sample_pose(&mut a);
        assert_eq!(p, ArmPose::sample(&mut b2));
        assert_eq!(p.shoulder_twist, 0.0);
    }
}

#[test]
fn shoulder_twist_turns_the_plane_the_elbow_bends_in() {
    // Twist 0: the flexed forearm points down (−Z); twist ±π/2: sideways (±Y), level
    // with the shoulder. A point on the forearm's axis, past the elbow, shows it.
    let limb = weft_mesh::limb::LimbParams::default();
    let elbow = limb.joint_position();
    let hand = Vector3::new(limb.length, 0.0, 0.0);
    let at = |twist: f64| {
        let pose = ArmPose {
            shoulder_twist: twist,
            elbow_flexion: 0.8,
            ..ArmPose::default()
        };
        pose.bone_transforms(&elbow)[1].apply(&hand)
    };
    let reach = (1.0 - limb.joint) * limb.length * 0.8f64.sin();
    let (down, left, right) = (
        at(0.0),
        at(std::f64::consts::FRAC_PI_2),
        at(-std::f64::consts::FRAC_PI_2),
    );
    assert!((down - Vector3::new(down.x, 0.0, -reach)).norm() < 1e-12, "{down:?}");
    assert!((left - Vector3::new(down.x, reach, 0.0)).norm() < 1e-12, "{left:?}");
    assert!((right - Vector3::new(down.x, -reach, 0.0)).norm() < 1e-12, "{right:?}");
}

#[test]
fn the_loose_sleeve_settles_onto_the_arm_and_hangs() {
    // 3 cm of slack: the sleeve falls onto the arm, by more than 5 mm on average even
    // where the arm is tilted steeply (up to 74°) and the slack slides along it instead —
    // five times the close-fitting sleeve's bound.
    let solved = assert_drapes(DrapeParams::loose_quick(), 5e-3);
    assert!(solved.iter().all(|e| e.settle_iterations > 0));
}

#[test]
fn bad_loose_sleeve_parameters_are_typed_errors_naming_them() {
    let cases: [(&str, fn(&mut DrapeParams)); 8] = [
        ("Poisson", |p| p.poisson = 0.5),
        ("elbow flexion range", |p| p.elbow_flexion = [0.8, 0.2]),
        ("shoulder range", |p| p.shoulder_range = 2.0),
        ("settle time step", |p| p.settle_time_step = 0.0),
        ("seam offset", |p| p.seam_offset = 0.05),
        ("gravity", |p| p.gravity = [0.0, 0.0, f64::NAN]),
        ("skinned guess half-width", |p| p.skinned_guess_half_width = -0.1),
        ("shoulder twist range", |p| p.twist_range = 2.0),
    ];
    for (name, spoil) in cases {
        let mut p = DrapeParams::loose_quick();
        spoil(&mut p);
        let e = Drape::new(p).unwrap_err().to_string();
        assert!(e.contains(name), "{name}: {e}");
    }
}

#[test]
fn a_guess_that_folds_the_sleeve_at_the_elbow_is_refused() {
    // Bound to the body 3 cm off it, the offsets cross at the inner elbow.
    let mut p = DrapeParams::loose();
    p.skinned_guess_half_width = 0.0;
    let e = Drape::new(p).unwrap_err().to_string();
    assert!(e.contains("folds"), "{e}");
    // Skinned with the sleeve's own weights, past the range the scene allows.
    let mut p = DrapeParams::loose();
    p.elbow_flexion = [0.1, 1.5];
    let e = Drape::new(p).unwrap_err().to_string();
    assert!(e.contains("folds"), "{e}");
}

#[test]
fn drape_parameters_round_trip_and_the_sleeves_json_is_unchanged() {
    // The sleeve's drape.json has no field of the loose sleeve's (its datasets' bytes).
    let json = serde_json::to_string(&DrapeParams::standard()).unwrap();
    for field in ["shoulder_range", "elbow_flexion", "twist", "settle", "skinned_guess"] {
        assert!(!json.contains(field), "{json}");
    }
    for p in [DrapeParams::standard(), DrapeParams::loose()] {
        let back: DrapeParams = serde_json::from_str(&serde_json::to_string(&p).unwrap()).unwrap();
        assert_eq!(back, p);
    }
}

#[test]
fn abduction_turns_the_draped_loose_sleeve_rigidly_about_the_vertical() {
    // Abduction is a rotation about the gravity axis applied to the whole arm: the body,
    // the sewn ring and the guess turn with it and gravity does not, so the equilibrium
    // is the abduction-free one turned (to the solver's tolerance).
    let d = Drape::new(DrapeParams::loose_quick()).unwrap();
    let pose = ArmPose {
        shoulder_flexion: 0.4,
        shoulder_twist: 0.5,
        elbow_flexion: 0.6,
        ..ArmPose::default()
    };
    let turned = ArmPose {
        shoulder_abduction: 0.7,
        ..pose
    };
    let (a, b) = (d.solve(&pose).unwrap(), d.solve(&turned).unwrap());
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.7);
    let expected: Vec<f64> = a
        .truth
        .chunks(3)
        .flat_map(|x| (r * Vector3::new(x[0], x[1], x[2])).data.0[0])
        .collect();
    let moved = max_diff(&a.truth, &a.guess);
    assert!(moved > 1e-2, "the sleeve moves centimetres ({moved} m)");
    let off = max_diff(&b.truth, &expected);
    assert!(off < 1e-4, "turned equilibrium off by {off} m");
}
