//! A newcomer's path with nothing but defaults: for every model kind, `cargo xtask dataset
//! <name> --size quick`, then `cargo xtask train <kind>` with no configuration file (one
//! epoch, to stay fast), then `cargo xtask score`. Defaults must fit the data they are
//! given: a quick `limb` sequence holds fewer frames than altconv's default window.

use std::path::{Path, PathBuf};
use std::process::Command;

const XTASK: &str = env!("CARGO_BIN_EXE_xtask");

fn ok(args: &[&str]) -> String {
    let out = Command::new(XTASK).args(args).output().expect("xtask runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{args:?}: {stderr}");
    stderr
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn dataset_train_and_score_work_with_defaults_for_every_model_kind() {
    let root: PathBuf = std::env::temp_dir().join(format!("weft-newcomer-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    for (kind, dataset, extra) in [
        ("altconv", "limb", &[][..]),
        ("nnwarp", "nnwarp", &["--material", "neo-hookean"][..]),
        ("embed", "sheet-ms", &[][..]),
        ("drape", "drape", &[][..]),
    ] {
        let (data, model, scores) = (root.join(dataset), root.join(kind), root.join(format!("{kind}-scores")));
        ok(&["dataset", dataset, "--size", "quick", "--quiet", "--out", s(&data)]);
        let mut train = vec![
            "train",
            kind,
            "--quiet",
            "--epochs",
            "1",
            "--data",
            s(&data),
            "--out",
            s(&model),
        ];
        train.extend_from_slice(extra);
        let said = ok(&train);
        if kind == "altconv" {
            assert!(
                said.contains("training on 8 steps"),
                "the window fitted to the data is said: {said}"
            );
        }
        ok(&[
            "score",
            kind,
            "--model",
            s(&model),
            "--data",
            s(&data),
            "--out",
            s(&scores),
        ]);
        let records: Vec<serde_json::Value> =
            serde_json::from_str(&std::fs::read_to_string(scores.join("results.json")).unwrap()).unwrap();
        assert!(!records.is_empty(), "{kind}: no records");
        assert!(
            records.iter().all(|r| r["value"].as_f64().is_some_and(f64::is_finite)),
            "{kind}: {records:?}"
        );
    }
    let _ = std::fs::remove_dir_all(&root);
}
