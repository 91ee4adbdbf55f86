//! Scenes that read their meshes from files in `fixtures/`, loaded through the one
//! `weft_sim::load`: a cloth scene from an OBJ must simulate exactly like the generated
//! sheet it was written from, and a TetGen bar under a linear static solve must respond
//! linearly to its load.

use std::path::PathBuf;

use weft_sim::scenes::cloth::MeshSpec;
use weft_sim::scenes::volume::VolumeSolve;
use weft_sim::{AnyScene, ClothSimulation, VolumeSimulation, load};

fn fixture(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fixtures").join(rel)
}

#[test]
fn cloth_scene_from_obj_matches_the_generated_sheet_bit_for_bit() {
    let loaded = load(fixture("scenes/curtain-from-obj.toml").to_str().unwrap(), false).unwrap();
    let AnyScene::Cloth(scene) = loaded.scene else {
        panic!("expected a cloth scene")
    };
    let mut from_file = ClothSimulation::new(scene.clone(), loaded.base_dir.as_deref()).unwrap();
    let mut generated_scene = scene;
    generated_scene.mesh = MeshSpec::Sheet { n: 4, size: 1.0 };
    let mut generated = ClothSimulation::new(generated_scene, None).unwrap();
    assert_eq!(from_file.mesh().positions(), generated.mesh().positions());
    for _ in 0..10 {
        let a = from_file.step().unwrap();
        let b = generated.step().unwrap();
        assert_eq!(a.positions, b.positions);
    }
    // The grasped corners moved along +X and the free bottom sagged under gravity.
    let x = from_file.integrator().positions();
    let rest = from_file.mesh().flat_positions();
    assert!(x[2] < rest[2], "bottom corner did not sag: {} vs {}", x[2], rest[2]);
}

#[test]
fn tetgen_bar_static_linear_response_is_linear_in_the_load_and_holds_its_anchors() {
    let path = fixture("scenes/bar-static-linear.toml");
    let loaded = load(path.to_str().unwrap(), false).unwrap();
    let AnyScene::Volume(scene) = loaded.scene else {
        panic!("expected a volume scene")
    };
    assert_eq!(scene.solve, VolumeSolve::StaticLinear);
    let displacement = |g: f64| {
        let mut s = scene.clone();
        s.gravity = Some([0.0, 0.0, g]);
        let mut sim = VolumeSimulation::new(s, loaded.base_dir.as_deref()).unwrap();
        sim.step().unwrap();
        let f = sim.step().unwrap(); // frame 2 of 2 carries the full load
        let rest = sim.mesh().flat_positions();
        (
            f.positions.iter().zip(&rest).map(|(a, b)| a - b).collect::<Vec<_>>(),
            sim.anchors().to_vec(),
        )
    };
    let (u1, anchors) = displacement(-9.81);
    let (u2, _) = displacement(-2.0 * 9.81);
    assert_eq!(anchors.len(), 4, "the x = 0 face of the 2×1×1 bar has 4 nodes");
    for &a in &anchors {
        assert_eq!(&u1[3 * a..3 * a + 3], &[0.0; 3]);
    }
    let tip = u1.iter().skip(2).step_by(3).fold(0.0f64, |m, z| m.min(*z));
    assert!(tip < -1e-7, "the free end did not deflect downwards: {tip}");
    for (a, b) in u1.iter().zip(&u2) {
        assert!((2.0 * a - b).abs() <= 1e-9 * b.abs().max(1e-12), "{a} × 2 ≠ {b}");
    }
}
