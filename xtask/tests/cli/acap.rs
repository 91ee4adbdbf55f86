//! `cargo xtask acap`: a simulated sheet's frames (the rest frame and three steps) encoded with pins, decoded back to meshes
//! from the recorded pins alone, and the round trip measured.

use std::process::Command;

const XTASK: &str = env!("CARGO_BIN_EXE_xtask");

fn ok(args: &[&str]) -> String {
    let out = Command::new(XTASK).args(args).output().expect("xtask runs");
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn encoded_frames_decode_from_their_recorded_pins_and_round_trip() {
    let root = std::env::temp_dir().join(format!("weft-acap-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let (sim, features, meshes) = (root.join("sim"), root.join("f.npy"), root.join("meshes"));
    let s = |p: &std::path::Path| p.to_str().unwrap().to_string();
    ok(&[
        "simulate",
        "sheet-ms",
        "--quick",
        "--frames",
        "3",
        "--quiet",
        "--out",
        &s(&sim),
    ]);
    let said = ok(&[
        "acap",
        "encode",
        "--rest",
        &s(&sim),
        "--out",
        &s(&features),
        "--pin",
        "0,1",
    ]);
    assert!(said.starts_with("wrote 4 frames"), "{said}");
    assert!(root.join("f.pins.npy").exists() && root.join("f.pins.json").exists());
    let said = ok(&[
        "acap",
        "decode",
        "--rest",
        &s(&sim),
        "--features",
        &s(&features),
        "--out-dir",
        &s(&meshes),
    ]);
    assert!(said.starts_with("wrote 4 meshes"), "{said}");
    assert!(meshes.join("frame_00003.obj").exists());
    // Encoding again without pins removes the earlier pin files.
    ok(&["acap", "encode", "--rest", &s(&sim), "--out", &s(&features)]);
    assert!(!root.join("f.pins.json").exists());
    let report: serde_json::Value = serde_json::from_str(&ok(&["acap", "roundtrip", "--sim", &s(&sim)])).unwrap();
    assert_eq!(report["frames"], 4);
    // The rest frame comes back to round-off; the moving frames within a few per cent of
    // the diagonal with only the two grasp points fixed.
    assert!(report["per_frame_max_rms"][0][0].as_f64().unwrap() < 1e-6, "{report}");
    assert!(report["worst_max_error"].as_f64().unwrap() < 0.05, "{report}");
    let _ = std::fs::remove_dir_all(&root);
}
