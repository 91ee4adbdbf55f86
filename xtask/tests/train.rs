//! `cargo xtask train embed` end to end on a quick dataset: every stage lowers its loss, a
//! run split by `--resume` ends bit for bit where an uninterrupted run does, and a model
//! directory is never overwritten by accident.

use std::path::{Path, PathBuf};
use std::process::Command;

const XTASK: &str = env!("CARGO_BIN_EXE_xtask");

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("weft-train-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn xtask(args: &[&str], dirs: &[(&str, &Path)]) -> std::process::Output {
    let mut c = Command::new(XTASK);
    c.args(args);
    for (flag, dir) in dirs {
        c.arg(flag).arg(dir);
    }
    c.output().expect("xtask runs")
}

/// `log.csv` rows as (stage, epoch, total).
fn log(model: &Path) -> Vec<(u8, usize, f64)> {
    std::fs::read_to_string(model.join("log.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[0].parse().unwrap(), f[1].parse().unwrap(), f[7].parse().unwrap())
        })
        .collect()
}

#[test]
fn train_embed_lowers_every_stage_and_resumes_bit_for_bit() {
    let root = scratch("embed");
    let data = root.join("data");
    let out = xtask(
        &["dataset", "sheet-ms", "--size", "quick", "--quiet"],
        &[("--out", &data)],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let config = root.join("config.json");
    std::fs::write(
        &config,
        r#"{"autoencoder": {"conv_layers": 1, "latent": 16}, "latent_hidden": [64], "epochs": [12, 12, 4], "batch": 8,
            "adam": {"learning_rate": 0.002, "beta1": 0.9, "beta2": 0.999, "epsilon": 1e-8}}"#,
    )
    .unwrap();
    let train = |model: &Path, extra: &[&str]| {
        let mut args = vec!["train", "embed", "--quiet"];
        args.extend(extra);
        xtask(&args, &[("--data", &data), ("--config", &config), ("--out", model)])
    };
    let straight = root.join("straight");
    let out = train(&straight, &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = log(&straight);
    assert_eq!(rows.len(), 28);
    for stage in 1..=3u8 {
        let totals: Vec<f64> = rows.iter().filter(|r| r.0 == stage).map(|r| r.2).collect();
        assert!(
            totals.last().unwrap() < totals.first().unwrap(),
            "stage {stage} did not lower its loss: {totals:?}"
        );
    }
    // Stage 1 alone, then the rest with --resume: the same bytes as the straight run.
    let split = root.join("split");
    assert!(train(&split, &["--stages", "1"]).status.success());
    let refused = train(&split, &[]);
    assert!(!refused.status.success(), "an existing model must not be overwritten");
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--resume"));
    assert!(train(&split, &["--resume"]).status.success());
    for file in [
        "checkpoint/autoencoder/params.safetensors",
        "checkpoint/simulator/params.safetensors",
        "checkpoint/autoencoder/optimizer.safetensors",
        "log.csv",
    ] {
        assert_eq!(
            std::fs::read(straight.join(file)).unwrap(),
            std::fs::read(split.join(file)).unwrap(),
            "{file} differs after resuming"
        );
    }
    // Resuming with another configuration is refused, not mixed.
    let changed = train(&split, &["--resume", "--no-pb"]);
    assert!(!changed.status.success());
    assert!(String::from_utf8_lossy(&changed.stderr).contains("configuration differs"));
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn train_nnwarp_corrects_held_out_poses_better_than_linear_and_modal_warping() {
    use std::sync::Arc;
    use weft_nn::nnwarp::{NnWarp, WarpContext, load_model, rel_error};
    let root = scratch("nnwarp");
    let data = root.join("data");
    let out = xtask(
        &["dataset", "nnwarp", "--size", "quick", "--sequences", "16", "--quiet"],
        &[("--out", &data)],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let config = root.join("config.json");
    std::fs::write(&config, r#"{"batch": 256, "epochs": 40}"#).unwrap();
    let model = root.join("model");
    let out = xtask(
        &["train", "nnwarp", "--material", "neo-hookean", "--quiet"],
        &[("--data", &data), ("--config", &config), ("--out", &model)],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // Refused without --resume; resumed it has nothing left to do.
    let again = xtask(
        &["train", "nnwarp", "--material", "neo-hookean", "--quiet"],
        &[("--data", &data), ("--config", &config), ("--out", &model)],
    );
    assert!(!again.status.success());
    let (_, mlp) = load_model(&model).unwrap();
    let set = weft_nn::data::WarpDataset::load(&data, "neo-hookean").unwrap();
    let grads = Arc::new(weft_sim::warp::NodalGradients::new(&set.body).unwrap());
    let mut tested = 0;
    // Summed errors over the directional test fields: NNWarp, modal warping.
    let mut directional = (0.0, 0.0);
    for s in set.sequences.iter().filter(|s| s.split == "test") {
        let context =
            WarpContext::with_gradients(&set.body, grads.clone(), &set.anchors, s.field, s.poisson, 1.0).unwrap();
        let warp = NnWarp::new(context, mlp.clone());
        let last = s.linear.len() - 1;
        let (lin, reference) = (&s.linear[last], &s.nonlinear[last]);
        let linear = rel_error(lin, reference);
        let nnwarp = rel_error(&warp.warp(lin).unwrap(), reference);
        let modal = rel_error(&weft_sim::warp::modal_warp(&grads, lin).unwrap(), reference);
        // Unseen force fields: the learned warp beats linear FEM by far, and on average
        // modal warping under directional fields (the ten training sequences hold only two
        // circular ones).
        assert!(
            nnwarp < 0.5 * linear,
            "sequence {}: nnwarp {nnwarp} vs linear {linear}",
            s.index
        );
        if matches!(s.field, weft_sim::warp::FieldDirection::Directional(_)) {
            directional.0 += nnwarp;
            directional.1 += modal;
        }
        tested += 1;
    }
    assert!(tested >= 3);
    assert!(directional.0 < 0.8 * directional.1, "{directional:?}");
    // The runtime command on the quick beam under gravity, against full FEM.
    let warp_out = root.join("warp");
    let out = xtask(
        &[
            "warp",
            "--scene",
            "beam-neo-hookean",
            "--quick",
            "--frames",
            "4",
            "--reference",
        ],
        &[("--model", &model), ("--out", &warp_out)],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(warp_out.join("summary.json")).unwrap()).unwrap();
    let frames = summary["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 4);
    assert!(
        frames
            .iter()
            .all(|f| f["rel_error_nnwarp"].as_f64().is_some_and(f64::is_finite))
    );
    let vtk = std::fs::read_to_string(warp_out.join("frame-0004.vtk")).unwrap();
    assert!(vtk.contains("displacement") && vtk.contains("error"));
    let cloth = xtask(
        &["warp", "--scene", "sheet-ms", "--quick"],
        &[("--model", &model), ("--out", &root.join("cloth"))],
    );
    assert!(!cloth.status.success());
    assert!(String::from_utf8_lossy(&cloth.stderr).contains("not a volumetric scene"));
}

fn progress(model: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(model.join("progress.json")).unwrap()).unwrap()
}

/// `cargo xtask train drape`: a learned-μ model continued with a larger `--epochs` ends where
/// an uninterrupted run does (its μ and Adam state restored; only the layer's warm starts,
/// kept in memory, begin cold after the restart), every epoch records μ and the spread of
/// its gradient, and a model directory is not continued under another μ.
#[test]
fn train_drape_continues_a_learned_mu_model_and_refuses_another_layer() {
    let root = scratch("drape");
    let data = root.join("data");
    let out = xtask(&["dataset", "drape", "--size", "quick", "--quiet"], &[("--out", &data)]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let config = root.join("config.json");
    std::fs::write(
        &config,
        r#"{"net": {"hidden": [16, 32], "offset_scale": 0.01}, "batch": 4}"#,
    )
    .unwrap();
    let net = root.join("net");
    let run = |model: &Path, extra: &[&str]| {
        let mut args = vec!["train", "drape", "--quiet"];
        args.extend_from_slice(extra);
        xtask(&args, &[("--data", &data), ("--config", &config), ("--out", model)])
    };
    let out = run(&net, &["--epochs", "20"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mu = ["--layer", "quasistatic", "--learn-mu", "global", "--mu", "1"];
    let with = |epochs: &'static str, resume: bool| {
        let mut a = mu.to_vec();
        a.extend(["--init", net.to_str().unwrap(), "--epochs", epochs]);
        if resume {
            a.push("--resume");
        }
        a
    };
    let (whole, split) = (root.join("whole"), root.join("split"));
    assert!(run(&whole, &with("3", false)).status.success());
    assert!(run(&split, &with("2", false)).status.success());
    assert!(
        !run(&split, &with("3", false)).status.success(),
        "continued without --resume"
    );
    let out = run(&split, &with("3", true));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (a, b) = (progress(&whole), progress(&split));
    assert_eq!(b["epochs_done"], 3);
    let record = |p: &serde_json::Value, e: usize, key: &str| p["history"][e][key].as_f64().unwrap();
    for e in 0..3 {
        let (ma, mb) = (record(&a, e, "mu"), record(&b, e, "mu"));
        assert!(
            (ma - mb).abs() <= 1e-3 * ma,
            "epoch {e}: μ {ma} uninterrupted, {mb} continued"
        );
        assert!(a["history"][e]["mu_gradient"]["batches"].as_u64() == Some(4));
    }
    // μ moved from its start: the continued run really trained it.
    assert!((record(&b, 2, "mu") - 1.0).abs() > 0.05);
    let scores: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(split.join("scores.json")).unwrap()).unwrap();
    assert!(scores["scores"]["test"]["sqrtmse-mm"].as_f64().unwrap().is_finite());
    // The second-half summary is the history's: epochs 2-3 of 3, their validation mean,
    // the last μ, and the upper median of |mean|/sd of μ's gradient.
    let half = &scores["second_half"];
    assert_eq!(half["epochs"], serde_json::json!([2, 3]));
    let val = (record(&b, 1, "validation_sqrtmse_mm") + record(&b, 2, "validation_sqrtmse_mm")) / 2.0;
    assert!((half["validation_sqrtmse_mm_mean"].as_f64().unwrap() - val).abs() <= 1e-12 * val);
    assert_eq!(half["last_mu"].as_f64(), Some(record(&b, 2, "mu")));
    let signal = |e: usize| {
        let g = &b["history"][e]["mu_gradient"];
        g["mean"].as_f64().unwrap().abs() / g["sd"].as_f64().unwrap()
    };
    assert_eq!(
        half["mu_gradient_mean_over_sd_median"].as_f64(),
        Some(signal(1).max(signal(2)))
    );
    // Another μ start in the same directory is refused, not mixed into it.
    let mut other = with("4", true);
    other[5] = "0.5";
    let out = run(&split, &other);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("another configuration"));
    // --scan-mu scores the kept network at fixed μ: at the model's own μ it reproduces the
    // validation score, and another μ changes it.
    let fixed = root.join("fixed");
    let args = [
        "--layer",
        "quasistatic",
        "--mu",
        "0.5",
        "--epochs",
        "1",
        "--scan-mu",
        "0.5,2",
    ];
    let mut a = args.to_vec();
    a.extend(["--init", net.to_str().unwrap()]);
    let out = run(&fixed, &a);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let read = |f: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(fixed.join(f)).unwrap()).unwrap()
    };
    let (scores, scan) = (read("scores.json"), read("mu-scan.json"));
    let at = |i: usize, key: &str| scan["scan"][i][key].as_f64().unwrap();
    let validation = scores["scores"]["validation"]["sqrtmse-mm"].as_f64().unwrap();
    assert!((at(0, "validation_sqrtmse_mm") - validation).abs() <= 1e-9 * validation);
    assert!((at(1, "validation_sqrtmse_mm") - validation).abs() > 1e-6 * validation);
    // The loss is the mean of squared per-example errors: at least the squared mean.
    assert!(at(0, "validation_loss_mm2") >= validation * validation * (1.0 - 1e-12));
    let mut bad = a.clone();
    bad[7] = "0.5,0";
    let out = run(&root.join("bad"), &bad);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--scan-mu"));
    let _ = std::fs::remove_dir_all(&root);
}
