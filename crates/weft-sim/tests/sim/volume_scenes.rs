//! Volumetric and soft-tissue scenes: built-ins, user files, solve choices agreeing.

use weft_mesh::generators;
use weft_sim::scenes::volume::{AnchorSpec, VolumeMeshSpec, VolumeSolve};
use weft_sim::{BUILTIN_VOLUME_SCENES, SoftTissueScene, VolumeScene, VolumeSimulation};

#[test]
fn builtin_volume_scenes_round_trip_and_run() {
    for name in BUILTIN_VOLUME_SCENES {
        let s = VolumeScene::builtin(name, true).unwrap();
        assert_eq!(VolumeScene::from_toml(&s.to_toml().unwrap()).unwrap(), s, "{name}");
        let mut sim = VolumeSimulation::new(s, None).unwrap();
        let rest = sim.mesh().flat_positions();
        let mut moved = 0.0f64;
        for _ in 0..3 {
            let f = sim.step().unwrap();
            assert!(f.positions.iter().all(|v| v.is_finite()));
            moved = f
                .positions
                .iter()
                .zip(&rest)
                .map(|(a, b)| (a - b).abs())
                .fold(moved, f64::max);
        }
        assert!(moved > 1e-6, "{name}: the load moved nothing");
        // Anchored nodes stay put.
        let anchors = sim.anchors().to_vec();
        let f = sim.step().unwrap();
        for a in anchors {
            assert!((0..3).all(|k| f.positions[3 * a + k] == rest[3 * a + k]));
        }
    }
}

#[test]
fn static_linear_and_quasistatic_linear_agree() {
    let mut s = VolumeScene::builtin("beam-static-linear", true).unwrap();
    s.frames = 2;
    let mut lin = VolumeSimulation::new(s.clone(), None).unwrap();
    s.solve = VolumeSolve::Quasistatic;
    let mut qs = VolumeSimulation::new(s, None).unwrap();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..2 {
        a = lin.step().unwrap().positions;
        b = qs.step().unwrap().positions;
    }
    let rest = lin.mesh().flat_positions();
    let scale = a.iter().zip(&rest).map(|(x, r)| (x - r).abs()).fold(0.0, f64::max);
    let diff = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    // Linear elasticity is quadratic: Newton and the pre-factorised solve find the same
    // minimiser, up to Newton's tolerance.
    assert!(
        diff < 1e-6 * scale.max(1e-12) + 1e-12,
        "diff {diff} vs displacement {scale}"
    );
}

#[test]
fn user_tet_files_anchors_and_errors() {
    let dir = std::env::temp_dir().join(format!("weft-volume-scenes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let beam = generators::t_beam(&generators::BeamParams {
        cells: [6, 3, 3],
        size: [1.0, 0.3, 0.3],
    })
    .unwrap();
    weft_mesh::io::write_tetgen(&dir.join("t.node"), &beam).unwrap();
    weft_mesh::io::write_vtk_tets(&dir.join("t.vtk"), beam.positions(), beam.tets(), &[]).unwrap();
    let mut s = VolumeScene::builtin("beam-neo-hookean", true).unwrap();
    for file in ["t.node", "t.vtk"] {
        s.mesh = VolumeMeshSpec::File { path: file.into() };
        s.anchors = AnchorSpec::Plane {
            point: [0.0, 0.0, 0.0],
            normal: [1.0, 0.0, 0.0],
            tolerance: 1e-9,
        };
        let mut sim = VolumeSimulation::new(s.clone(), Some(&dir)).unwrap();
        assert_eq!(sim.mesh(), &beam);
        assert!(!sim.anchors().is_empty());
        sim.step().unwrap();
    }
    s.anchors = AnchorSpec::Indices { indices: vec![] };
    assert!(VolumeSimulation::new(s.clone(), Some(&dir)).is_err());
    s.anchors = AnchorSpec::Indices {
        indices: vec![1_000_000],
    };
    assert!(VolumeSimulation::new(s.clone(), Some(&dir)).is_err());
    s.anchors = AnchorSpec::Min {
        axis: 0,
        tolerance: 1e-9,
    };
    s.poisson = 0.5;
    assert!(VolumeSimulation::new(s.clone(), Some(&dir)).is_err());
    s.poisson = 0.3;
    s.mesh = VolumeMeshSpec::File {
        path: "missing.node".into(),
    };
    assert!(VolumeSimulation::new(s, Some(&dir)).is_err());
}

#[test]
fn soft_tissue_scene_round_trips_and_builds() {
    let s = SoftTissueScene::builtin(true);
    assert_eq!(SoftTissueScene::from_toml(&s.to_toml().unwrap()).unwrap(), s);
    let mut sim = s.build().unwrap();
    sim.step_frame().unwrap();
    assert_eq!(sim.skinned_surface().len(), sim.simulated_surface().len());
    assert!(SoftTissueScene::from_toml("type = \"soft-tissue\"\nname = \"x\"").is_err());
}
