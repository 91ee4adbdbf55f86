//! `cargo xtask score`: each of the four model kinds, trained briefly on a quick dataset of
//! seed 0, is scored on a quick dataset of seed 1 (data it never saw) into `results.json`
//! records in the evaluation's names with their predictions; a model scored on a dataset
//! of another kind is a typed error naming the problem.

use std::path::{Path, PathBuf};
use std::process::Command;

const XTASK: &str = env!("CARGO_BIN_EXE_xtask");

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("weft-score-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn run(args: &[&str]) -> std::process::Output {
    Command::new(XTASK).args(args).output().expect("xtask runs")
}

fn ok(args: &[&str]) {
    let out = run(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Generates the quick dataset `name` with `seed` into `dir`.
fn dataset(name: &str, seed: &str, dir: &Path, extra: &[&str]) {
    let mut a = vec![
        "dataset",
        name,
        "--size",
        "quick",
        "--quiet",
        "--seed",
        seed,
        "--out",
        s(dir),
    ];
    a.extend_from_slice(extra);
    ok(&a);
}

/// Scores and returns the records, checking each names the experiment, is finite, and that
/// the predictions were written.
fn score(kind: &str, model: &Path, data: &Path, out: &Path) -> Vec<serde_json::Value> {
    ok(&["score", kind, "--model", s(model), "--data", s(data), "--out", s(out)]);
    let records: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert!(!records.is_empty());
    for r in &records {
        assert_eq!(r["experiment"], kind);
        assert!(r["value"].as_f64().unwrap().is_finite(), "{r}");
        assert_eq!(r.as_object().unwrap().len(), 11, "the results.json record format: {r}");
    }
    let predictions = out.join("predictions").join(kind);
    assert!(predictions.is_dir(), "{} missing", predictions.display());
    records
}

fn value(records: &[serde_json::Value], method: &str, metric: &str) -> f64 {
    records
        .iter()
        .find(|r| r["method"] == method && r["metric"] == metric)
        .unwrap_or_else(|| panic!("no {method}/{metric} in {records:?}"))["value"]
        .as_f64()
        .unwrap()
}

#[test]
fn every_model_kind_is_scored_on_a_dataset_of_another_seed() {
    let root = scratch("all");
    // Alt-ConvLSTM on the limb.
    let (limb0, limb1) = (root.join("limb0"), root.join("limb1"));
    dataset("limb", "0", &limb0, &["--frames", "12"]);
    dataset("limb", "1", &limb1, &["--frames", "12"]);
    let config = root.join("altconv.json");
    std::fs::write(&config, r#"{"hidden": [8, 8], "steps": 4, "batch": 1}"#).unwrap();
    let alt = root.join("alt");
    ok(&[
        "train",
        "altconv",
        "--quiet",
        "--epochs",
        "2",
        "--data",
        s(&limb0),
        "--config",
        s(&config),
        "--out",
        s(&alt),
    ]);
    let r = score("altconv", &alt, &limb1, &root.join("score-alt"));
    assert!(value(&r, "alt-convlstm", "error-mm-step1") > 0.0);
    assert!(value(&r, "skinning", "error-mm-rollout10") > 0.0);
    assert!(r.iter().all(|r| r["split"] == "test"));
    // The other seed's sequences are other motions: the scores differ from the training seed's.
    let same = score("altconv", &alt, &limb0, &root.join("score-alt-0"));
    assert_ne!(
        value(&r, "skinning", "error-mm-rollout10"),
        value(&same, "skinning", "error-mm-rollout10")
    );

    // NNWarp on the beam.
    let (warp0, warp1) = (root.join("warp0"), root.join("warp1"));
    dataset("nnwarp", "0", &warp0, &["--sequences", "32"]);
    dataset("nnwarp", "1", &warp1, &["--sequences", "8"]);
    let nn = root.join("nn");
    ok(&[
        "train",
        "nnwarp",
        "--quiet",
        "--material",
        "neo-hookean",
        "--epochs",
        "20",
        "--data",
        s(&warp0),
        "--out",
        s(&nn),
    ]);
    let r = score("nnwarp", &nn, &warp1, &root.join("score-nn"));
    assert!(value(&r, "nnwarp", "rel-error") < value(&r, "linear", "rel-error"));

    // The embedding on a cloth scene.
    let (cloth0, cloth1) = (root.join("cloth0"), root.join("cloth1"));
    dataset("sheet-ms", "0", &cloth0, &[]);
    dataset("sheet-ms", "1", &cloth1, &[]);
    let config = root.join("embed.json");
    std::fs::write(
        &config,
        r#"{"autoencoder": {"conv_layers": 1, "latent": 8}, "latent_hidden": [16], "epochs": [2, 1, 1]}"#,
    )
    .unwrap();
    let emb = root.join("emb");
    ok(&[
        "train",
        "embed",
        "--quiet",
        "--data",
        s(&cloth0),
        "--config",
        s(&config),
        "--out",
        s(&emb),
    ]);
    let r = score("embed", &emb, &cloth1, &root.join("score-emb"));
    assert!(value(&r, "ours", "m-rms") > 0.0);
    // The validation windows: M_phys with its two forces apart, beside the ground truth's,
    // which balance to the solver's tolerance.
    let out = root.join("score-emb-validation");
    ok(&[
        "score",
        "embed",
        "--model",
        s(&emb),
        "--data",
        s(&cloth1),
        "--split",
        "validation",
        "--out",
        s(&out),
    ]);
    let v: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert!(v.iter().all(|r| r["split"] == "validation"), "{v:?}");
    for metric in ["m-phys", "m-phys-inertial", "m-phys-potential"] {
        assert!(value(&v, "ours", metric) >= 0.0);
        assert!(value(&v, "ground-truth", metric) >= 0.0);
    }
    assert!(value(&v, "ours", "m-rms") > 0.0 && value(&v, "ours", "ephys-parity") > 0.0);
    assert!(value(&v, "ground-truth", "m-phys") < 1e-6 * value(&v, "ground-truth", "m-phys-inertial"));
    let refused = run(&[
        "score",
        "embed",
        "--model",
        s(&emb),
        "--data",
        s(&cloth1),
        "--split",
        "train",
        "--out",
        s(&root.join("refused")),
    ]);
    assert!(!refused.status.success());
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--split test or --split validation"));

    // A drape network.
    let (drape0, drape1) = (root.join("drape0"), root.join("drape1"));
    dataset("drape", "0", &drape0, &[]);
    dataset("drape", "1", &drape1, &[]);
    let config = root.join("drape.json");
    std::fs::write(
        &config,
        r#"{"net": {"hidden": [16, 32], "offset_scale": 0.01}, "batch": 4}"#,
    )
    .unwrap();
    let net = root.join("net");
    ok(&[
        "train",
        "drape",
        "--quiet",
        "--epochs",
        "3",
        "--data",
        s(&drape0),
        "--config",
        s(&config),
        "--out",
        s(&net),
    ]);
    let r = score("drape", &net, &drape1, &root.join("score-drape"));
    assert!(value(&r, "network-only", "sqrtmse-mm") > 0.0);
    assert!(value(&r, "network-only", "maxdist-mm") >= value(&r, "network-only", "sqrtmse-mm"));

    // A model scored on a dataset of another kind is refused by name.
    let wrong = run(&[
        "score",
        "altconv",
        "--model",
        s(&alt),
        "--data",
        s(&drape1),
        "--out",
        s(&root.join("wrong")),
    ]);
    assert!(!wrong.status.success());
    assert!(
        String::from_utf8_lossy(&wrong.stderr).contains("limb"),
        "{}",
        String::from_utf8_lossy(&wrong.stderr)
    );
    let _ = std::fs::remove_dir_all(&root);
}
