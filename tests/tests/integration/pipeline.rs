//! Cross-crate pipeline: simulate a built-in scene, encode its frames as ACAP features,
//! decode them with only the grasp points pinned, and measure the reconstruction error
//! relative to the bounding-box diagonal (Tan et al. §IV-A; issue: ACAP round trip on
//! sheet-ms, sheet-fem and ball-fem frames).

use weft_acap::{AcapFeatures, AcapSettings, PoissonPseudoInverse, ReconstructionError};
use weft_mesh::unflatten;
use weft_sim::{ClothScene, ClothSimulation};

fn round_trip(scene: &str, frames: usize, n: Option<usize>) -> (f64, f64) {
    let mut s = ClothScene::builtin(scene, true).unwrap();
    if let Some(n) = n {
        s.mesh = weft_sim::scenes::cloth::MeshSpec::Sheet { n, size: 1.0 };
    }
    let mut sim = ClothSimulation::new(s, None).unwrap();
    let features = AcapFeatures::new(sim.mesh(), AcapSettings::default()).unwrap();
    let pins = sim.grasp_vertices().to_vec();
    let inverse = PoissonPseudoInverse::new(&features, &pins).unwrap();
    let (mut worst_max, mut worst_rms) = (0.0f64, 0.0f64);
    for _ in 0..frames {
        let frame = sim.step().unwrap();
        let p = unflatten(&frame.positions);
        let f = features.encode(&p).unwrap();
        let pin_positions: Vec<_> = pins.iter().map(|&i| p[i]).collect();
        let back = inverse.decode(&f, &pin_positions).unwrap();
        let e = ReconstructionError::between(&p, &back).unwrap();
        worst_max = worst_max.max(e.max_relative());
        worst_rms = worst_rms.max(e.rms_relative());
    }
    eprintln!("{scene}: worst max {worst_max:.3e}, worst RMS {worst_rms:.3e} of the bounding-box diagonal");
    (worst_max, worst_rms)
}

#[test]
fn acap_round_trip_on_simulated_sheet_ms_frames() {
    let (max, rms) = round_trip("sheet-ms", 25, Some(17));
    assert!(max < 1e-2 && rms < 5e-3, "max {max}, rms {rms}");
}

#[test]
fn acap_round_trip_on_simulated_sheet_fem_frames() {
    let (max, rms) = round_trip("sheet-fem", 25, Some(17));
    assert!(max < 1e-2 && rms < 5e-3, "max {max}, rms {rms}");
}

#[test]
fn acap_round_trip_on_simulated_ball_fem_frames() {
    let (max, rms) = round_trip("ball-fem", 25, None);
    assert!(max < 1e-2 && rms < 5e-3, "max {max}, rms {rms}");
}
