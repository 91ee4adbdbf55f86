//! The guarded roll-out from the command line (docs/GUARD.md, "Your own scene"): a
//! surrogate fitted with `train inertial-correction` on the quick `sheet-ms`, then
//! `simulate --surrogate --tolerance`; bad tolerances and mismatched scenes are errors
//! naming the problem.

use super::{arg, xtask, xtask_ok};

#[test]
fn a_surrogate_is_fitted_then_run_under_the_guard() {
    let root = std::env::temp_dir().join(format!("weft-cli-guard-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let (data, model, run) = (root.join("data"), root.join("model"), root.join("run"));
    xtask_ok(&["dataset", "sheet-ms", "--size", "quick", "--quiet", "--out", arg(&data)]);
    let said = xtask_ok(&[
        "train",
        "inertial-correction",
        "--data",
        arg(&data),
        "--out",
        arg(&model),
    ]);
    assert!(said.contains("test one-step M_rms"), "{said}");
    // A second fit into the same directory is refused: nothing is overwritten.
    let again = xtask(&[
        "train",
        "inertial-correction",
        "--data",
        arg(&data),
        "--out",
        arg(&model),
    ]);
    assert!(!again.status.success() && String::from_utf8_lossy(&again.stderr).contains("already holds a model"));
    let said = xtask_ok(&[
        "simulate",
        "sheet-ms",
        "--quick",
        "--frames",
        "12",
        "--surrogate",
        arg(&model),
        "--tolerance",
        "0.5",
        "--quiet",
        "--out",
        arg(&run),
    ]);
    assert!(said.contains("under the guard (inertial-correction)"), "{said}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("guard.json")).unwrap()).unwrap();
    assert_eq!(report["per_frame"].as_array().unwrap().len(), 12);
    let t = &report["totals"];
    let counted = ["accepted", "corrected", "rejected"]
        .map(|k| t[k].as_u64().unwrap())
        .iter()
        .sum::<u64>();
    assert_eq!(counted, 12);
    assert!(run.join("frames.safetensors").is_file());
    for (args, says) in [
        (vec!["--tolerance", "-1"], "guard tolerance (mm)"),
        (vec!["--tolerance", "loose"], "a number of millimetres or `truth`"),
    ] {
        let mut all = vec![
            "simulate",
            "sheet-ms",
            "--quick",
            "--surrogate",
            arg(&model),
            "--out",
            arg(&run),
        ];
        all.extend(args);
        let out = xtask(&all);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && stderr.contains(says), "{stderr}");
    }
    // A surrogate of another scene, and a scene without a guard.
    for (scene, says) in [
        ("sheet-fem", "its scene is sheet-ms"),
        ("beam-linear", "needs a cloth scene"),
    ] {
        let out = xtask(&[
            "simulate",
            scene,
            "--quick",
            "--surrogate",
            arg(&model),
            "--out",
            arg(&run),
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && stderr.contains(says), "{stderr}");
    }
    let _ = std::fs::remove_dir_all(&root);
}
