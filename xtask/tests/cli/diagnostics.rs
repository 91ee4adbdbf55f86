//! `cargo xtask altconv-diagnostics`: a quick Alt-ConvLSTM trained in the test is rolled
//! out on its dataset's validation split; the JSON report holds every step and layer and
//! the printed table the chosen steps; a split without sequences is an error naming it.

use std::path::{Path, PathBuf};
use std::process::Command;

const XTASK: &str = env!("CARGO_BIN_EXE_xtask");

fn run(args: &[&str]) -> std::process::Output {
    Command::new(XTASK).args(args).output().expect("xtask runs")
}

fn ok(args: &[&str]) -> String {
    let out = run(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn the_diagnostics_of_a_quick_model_hold_every_step_and_layer() {
    let root: PathBuf = std::env::temp_dir().join(format!("weft-diagnostics-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let data = root.join("limb");
    ok(&[
        "dataset",
        "limb",
        "--size",
        "quick",
        "--quiet",
        "--frames",
        "12",
        "--out",
        s(&data),
    ]);
    let config = root.join("altconv.json");
    std::fs::write(&config, r#"{"hidden": [8, 8], "steps": 4, "batch": 1}"#).unwrap();
    let model = root.join("alt");
    ok(&[
        "train",
        "altconv",
        "--quiet",
        "--epochs",
        "2",
        "--data",
        s(&data),
        "--config",
        s(&config),
        "--out",
        s(&model),
    ]);
    let json = root.join("diagnostics.json");
    let args = [
        "altconv-diagnostics",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--out",
        s(&json),
    ];
    let table = ok(&args);
    let report: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    // `--frames 12` after the initial frame: the default 50 steps are cut to the 12 the
    // sequences hold.
    assert_eq!(report["steps"], 12);
    assert_eq!(report["split"], "validation");
    assert_eq!(report["variant"], "alt-convlstm");
    assert_eq!(report["layers"], serde_json::json!(["cell0", "cell1", "out"]));
    let steps = report["per_step"].as_array().unwrap();
    assert_eq!(steps.len(), 12);
    for (k, d) in steps.iter().enumerate() {
        assert_eq!(d["step"], k + 1);
        assert!(d["rollout_error_mm"].as_f64().unwrap() > 0.0);
        let layers = d["layers"].as_array().unwrap();
        assert_eq!(layers.len(), 3);
        for x in layers {
            for gate in ["input_gate", "forget_gate", "output_gate"] {
                let (mean, shut) = (x[gate]["mean"].as_f64().unwrap(), x[gate]["shut"].as_f64().unwrap());
                assert!((0.0..=1.0).contains(&mean) && (0.0..=1.0).contains(&shut), "{x}");
            }
            assert!(x["cell_abs_mean"].as_f64().unwrap() >= 0.0);
            // Alt-ConvLSTM accumulates in every layer.
            assert!(x["accumulation_abs_mean"].as_f64().unwrap() >= 0.0);
        }
    }
    let gradients = report["gradients"].as_array().unwrap();
    assert_eq!(gradients.len(), 3);
    for g in gradients {
        assert!(
            g["rms"].as_f64().unwrap() > 0.0 && g["parameters"].as_u64().unwrap() > 0,
            "{g}"
        );
    }
    // The table: steps 1, 5 and 10 of each layer (25 and 50 lie beyond the roll-out).
    for layer in ["cell0", "cell1", "out"] {
        let rows: Vec<&str> = table.lines().filter(|l| l.starts_with(layer)).collect();
        assert_eq!(rows.len(), 3, "{table}");
    }
    assert!(table.contains("gradient RMS before clipping"), "{table}");

    let out = run(&[
        "altconv-diagnostics",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--split",
        "nonsense",
        "--out",
        s(&json),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("nonsense"));
    let _ = std::fs::remove_dir_all(&root);
}
