//! `cargo xtask embed-diagnostics`: on the quick `sheet-ms` and a stage 1 trained in the
//! test, `gradients` logs every stage-1 term at the three checkpoints with λ_ephys
//! calibrated to the ratio asked for, and `floor` writes the true frames and each rank,
//! split by region; bad arguments are errors naming them.

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

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn the_gradient_log_and_the_floor_of_a_quick_sheet() {
    let root: PathBuf = std::env::temp_dir().join(format!("weft-embed-diagnostics-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let data = root.join("sheet-ms");
    ok(&["dataset", "sheet-ms", "--size", "quick", "--quiet", "--out", s(&data)]);
    let config = root.join("c.json");
    std::fs::write(
        &config,
        r#"{"autoencoder": {"conv_layers": 1, "latent": 8}, "latent_hidden": [16], "epochs": [2, 0, 0], "phys_scale": "curvature"}"#,
    )
    .unwrap();
    let model = root.join("model");
    ok(&[
        "train",
        "embed",
        "--quiet",
        "--stages",
        "1",
        "--data",
        s(&data),
        "--config",
        s(&config),
        "--out",
        s(&model),
    ]);

    let grad = root.join("out").join("gradients.json");
    let args = [
        "embed-diagnostics",
        "gradients",
        "--model",
        s(&model),
        "--data",
        s(&data),
        "--windows",
        "6",
    ];
    let table = ok(&[&args[..], &["--ratio", "0.5", "--out", s(&grad)]].concat());
    let log = json(&grad);
    assert_eq!(log["ratio"], 0.5);
    let checkpoints = log["checkpoints"].as_array().unwrap();
    let names: Vec<&str> = checkpoints.iter().map(|c| c["checkpoint"].as_str().unwrap()).collect();
    assert_eq!(names, ["init", "best", "last"]);
    assert_eq!(checkpoints[0]["epoch"], 0);
    assert_eq!(checkpoints[2]["epoch"], 2);
    for c in checkpoints {
        assert_eq!(c["norms"]["windows"], 6);
        let terms = c["norms"]["terms"].as_array().unwrap();
        let names: Vec<&str> = terms.iter().map(|t| t["term"].as_str().unwrap()).collect();
        assert_eq!(names, ["recon", "vert", "ephys"]);
        let cal = &c["calibration"];
        let top = terms[..2]
            .iter()
            .map(|t| t["weighted_norm"].as_f64().unwrap())
            .fold(0.0, f64::max);
        let pulled = cal["ephys_weight"].as_f64().unwrap() * terms[2]["norm"].as_f64().unwrap();
        assert!((pulled / top - 0.5).abs() < 1e-9, "{cal}");
    }
    assert!(table.contains("λ_ephys for 0.5 ×"), "{table}");

    let floor = root.join("floor.json");
    let table = ok(&[
        "embed-diagnostics",
        "floor",
        "--data",
        s(&data),
        "--ranks",
        "4,8",
        "--near",
        "0.2",
        "--out",
        s(&floor),
    ]);
    let report = json(&floor);
    let rows = report["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    assert!(rows[0]["rank"].is_null() && rows[1]["rank"] == 4 && rows[2]["rank"] == 8);
    for r in rows {
        let (near, far) = (
            r["near"]["total"].as_f64().unwrap(),
            r["far"]["total"].as_f64().unwrap(),
        );
        let m_phys = r["m_phys"].as_f64().unwrap();
        assert!((near + far - m_phys).abs() <= 1e-12 * m_phys, "{r}");
        assert!(r["far"]["forces"]["inertia"].as_f64().unwrap() > 0.0, "{r}");
    }
    // More components, a lower floor; the true frames balance to the solver's tolerance.
    let m = |k: usize| rows[k]["m_phys"].as_f64().unwrap();
    assert!(m(0) < 1e-6 * m(2) && m(2) < m(1), "{rows:?}");
    assert!(table.contains("rank truth") && table.contains("rank 8 (8)"), "{table}");

    for (bad, named) in [
        (
            vec!["floor", "--data", s(&data), "--ranks", "0", "--out", s(&floor)],
            "rank",
        ),
        (
            vec!["floor", "--data", s(&data), "--near", "-1", "--out", s(&floor)],
            "near-grasp",
        ),
        (
            vec![
                "gradients",
                "--model",
                s(&model),
                "--data",
                s(&data),
                "--windows",
                "0",
                "--out",
                s(&grad),
            ],
            "--windows",
        ),
        (
            vec![
                "gradients",
                "--model",
                s(&model),
                "--data",
                s(&data),
                "--ratio",
                "0",
                "--out",
                s(&grad),
            ],
            "ratio",
        ),
    ] {
        let out = run(&[&["embed-diagnostics"][..], &bad].concat());
        assert!(!out.status.success(), "{bad:?}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains(named),
            "{bad:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let help = ok(&["embed-diagnostics", "gradients", "--help"]);
    assert!(help.contains("--ratio") && help.contains("--windows"), "{help}");
    let _ = std::fs::remove_dir_all(&root);
}
