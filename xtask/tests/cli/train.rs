//! `cargo xtask train` end to end on quick datasets, every model through the one trainer:
//! every stage lowers its loss, a run split by `--resume` ends bit for bit where an
//! uninterrupted run does, the kept weights are those of the best validation epoch, bad
//! configurations are refused by field before anything is written, and a model directory
//! is never overwritten by accident.

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

/// A run's `training.json`.
fn state(run: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(run.join("training.json")).unwrap()).unwrap()
}

/// Per epoch (loss, validation) of a run: what a resumed run must reproduce exactly.
fn history(run: &Path) -> Vec<(f64, f64)> {
    state(run)["history"]
        .as_array()
        .unwrap()
        .iter()
        .map(|h| (h["loss"].as_f64().unwrap(), h["validation"].as_f64().unwrap()))
        .collect()
}

/// The kept epoch is the one with the lowest validation score, the starting weights
/// (epoch 0) included, and `best/` holds exactly its weights.
fn assert_selected_on_validation(run: &Path) {
    let s = state(run);
    let mut best = (0, s["initial_validation"].as_f64().unwrap());
    for (e, (_, v)) in history(run).into_iter().enumerate() {
        if v < best.1 {
            best = (e + 1, v);
        }
    }
    assert_eq!(s["best_epoch"].as_u64(), Some(best.0 as u64), "{}", run.display());
    assert_eq!(s["best_validation"].as_f64(), Some(best.1));
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
    for (stage, epochs) in [(1, 12), (2, 12), (3, 4)] {
        let run = straight.join(format!("stage-{stage}"));
        let totals: Vec<f64> = history(&run).iter().map(|h| h.0).collect();
        assert_eq!(totals.len(), epochs);
        assert!(
            totals.last().unwrap() < totals.first().unwrap(),
            "stage {stage} did not lower its loss: {totals:?}"
        );
        assert_selected_on_validation(&run);
    }
    // Stage 1 alone, then the rest with --resume: the same bytes as the straight run.
    let split = root.join("split");
    assert!(train(&split, &["--stages", "1"]).status.success());
    let refused = train(&split, &[]);
    assert!(!refused.status.success(), "an existing model must not be overwritten");
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--resume"));
    assert!(train(&split, &["--resume"]).status.success());
    for stage in 1..=3 {
        let run = format!("stage-{stage}");
        assert_eq!(history(&straight.join(&run)), history(&split.join(&run)), "{run}");
    }
    for file in [
        "stage-1/best/autoencoder/params.safetensors",
        "stage-3/best/autoencoder/params.safetensors",
        "stage-3/best/simulator/params.safetensors",
        "stage-3/last/autoencoder/optimizer.safetensors",
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
    assert!(String::from_utf8_lossy(&changed.stderr).contains("another configuration"));
    // A bad configuration is refused by field before anything is written.
    std::fs::write(&config, r#"{"batch": 0}"#).unwrap();
    let bad = root.join("bad");
    let out = train(&bad, &[]);
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("`batch`"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!bad.exists(), "nothing is written for a refused configuration");
    let _ = std::fs::remove_dir_all(&root);
}

#[test]
fn train_nnwarp_corrects_held_out_poses_better_than_linear_and_modal_warping() {
    use std::sync::Arc;
    use weft_nn::nnwarp::{NnWarp, WarpContext, load_model, rel_error};
    let root = scratch("nnwarp");
    let data = root.join("data");
    let out = xtask(
        &["dataset", "nnwarp", "--size", "quick", "--sequences", "32", "--quiet"],
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
    assert_selected_on_validation(&model);
    // 4 epochs straight, and 2 + 2 with --resume: the same run, bit for bit.
    let (straight, split) = (root.join("straight"), root.join("split"));
    let short = |out: &Path, extra: &[&str]| {
        let mut a = vec!["train", "nnwarp", "--material", "neo-hookean", "--quiet"];
        a.extend_from_slice(extra);
        let o = xtask(&a, &[("--data", &data), ("--config", &config), ("--out", out)]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    short(&straight, &["--epochs", "4"]);
    short(&split, &["--epochs", "2"]);
    short(&split, &["--epochs", "4", "--resume"]);
    assert_eq!(history(&straight), history(&split));
    for f in [
        "best/net/params.safetensors",
        "last/net/params.safetensors",
        "last/net/optimizer.safetensors",
    ] {
        assert_eq!(
            std::fs::read(straight.join(f)).unwrap(),
            std::fs::read(split.join(f)).unwrap(),
            "{f}"
        );
    }
    let (_, mlp) = load_model(&model).unwrap();
    eprintln!("nnwarp kept epoch {} of 40", state(&model)["best_epoch"]);
    let set = weft_data::WarpDataset::load(&data, "neo-hookean").unwrap();
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
        // circular ones). The worst is a field mostly along the beam's axis (sequence 26,
        // 0.54× linear since the ramp solves in the runtime's regime, issue 70; the others
        // 0.11–0.36×).
        assert!(
            nnwarp < 0.6 * linear,
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
    assert!(!String::from_utf8_lossy(&out.stderr).contains("warning"));
    // On a beam of another material the model runs, with a warning naming both.
    let stvk = xtask(
        &["warp", "--scene", "beam-stvk", "--quick", "--frames", "1"],
        &[("--model", &model), ("--out", &root.join("stvk"))],
    );
    assert!(stvk.status.success(), "{}", String::from_utf8_lossy(&stvk.stderr));
    let stderr = String::from_utf8_lossy(&stvk.stderr);
    assert!(
        stderr.contains("trained on neo-hookean, but beam-stvk is stvk"),
        "{stderr}"
    );
    let cloth = xtask(
        &["warp", "--scene", "sheet-ms", "--quick"],
        &[("--model", &model), ("--out", &root.join("cloth"))],
    );
    assert!(!cloth.status.success());
    assert!(String::from_utf8_lossy(&cloth.stderr).contains("not a volumetric scene"));
}

fn progress(model: &Path) -> serde_json::Value {
    state(model)
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
    assert_selected_on_validation(&net);
    // A data-size study trains on the first N training examples; more than there are is
    // refused by name before anything is written.
    let few = root.join("few");
    let out = run(&few, &["--epochs", "2", "--train-examples", "4"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && err.contains("4 training and 4 validation"),
        "{err}"
    );
    let too_many = root.join("too-many");
    let out = run(&too_many, &["--epochs", "2", "--train-examples", "17"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--train-examples 17") && err.contains("16 training"),
        "{err}"
    );
    assert!(!too_many.exists());
    // The network alone (no layer, no warm starts) resumes bit for bit.
    let half = root.join("half");
    assert!(run(&half, &["--epochs", "10"]).status.success());
    assert!(run(&half, &["--epochs", "20", "--resume"]).status.success());
    assert_eq!(history(&net), history(&half));
    for f in ["best/net/params.safetensors", "last/net/optimizer.safetensors"] {
        assert_eq!(
            std::fs::read(net.join(f)).unwrap(),
            std::fs::read(half.join(f)).unwrap(),
            "{f}"
        );
    }
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
    let record = |p: &serde_json::Value, e: usize, key: &str| {
        let h = &p["history"][e];
        h[key].as_f64().or_else(|| h["extra"][key].as_f64()).unwrap()
    };
    for e in 0..3 {
        let (ma, mb) = (record(&a, e, "mu"), record(&b, e, "mu"));
        assert!(
            (ma - mb).abs() <= 1e-3 * ma,
            "epoch {e}: μ {ma} uninterrupted, {mb} continued"
        );
        assert!(record(&a, e, "mu_gradient_sd") > 0.0);
    }
    assert_selected_on_validation(&whole);
    // μ moved from its start: the continued run really trained it.
    assert!((record(&b, 2, "mu") - 1.0).abs() > 0.05);
    let scores: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(split.join("scores.json")).unwrap()).unwrap();
    assert!(scores["scores"]["test"]["sqrtmse-mm"].as_f64().unwrap().is_finite());
    // The second-half summary is the history's: epochs 2-3 of 3, their validation mean,
    // the last μ, and the upper median of |mean|/sd of μ's gradient.
    let half = &scores["second_half"];
    assert_eq!(half["epochs"], serde_json::json!([2, 3]));
    let val = (record(&b, 1, "validation") + record(&b, 2, "validation")) / 2.0;
    assert!((half["validation_sqrtmse_mm_mean"].as_f64().unwrap() - val).abs() <= 1e-12 * val);
    assert_eq!(half["last_mu"].as_f64(), Some(record(&b, 2, "mu")));
    let signal = |e: usize| record(&b, e, "mu_gradient_mean").abs() / record(&b, e, "mu_gradient_sd");
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

/// `cargo xtask train altconv` on the quick `limb-jiggle` dataset: a short teacher-forced
/// run of the position model lowers its training loss, validation is scored as a roll-out
/// (`recipe.validation_rollout`, stored with the model) and the kept epoch is the best one
/// by that score.
#[test]
fn train_altconv_on_the_jiggling_limb_lowers_the_loss() {
    let root = scratch("altconv-jiggle");
    let data = root.join("data");
    let out = xtask(
        &["dataset", "limb-jiggle", "--size", "quick", "--quiet"],
        &[("--out", &data)],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let config = root.join("config.json");
    std::fs::write(
        &config,
        r#"{"hidden": [8, 8], "steps": 6, "batch": 1, "epochs": 6, "recipe": {"validation_rollout": true}}"#,
    )
    .unwrap();
    let model = root.join("model");
    let o = xtask(
        &[
            "train",
            "altconv",
            "--model",
            "convlstm-np-y",
            "--quiet",
            "--lr",
            "0.01",
        ],
        &[("--data", &data), ("--config", &config), ("--out", &model)],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let h = history(&model);
    assert_eq!(h.len(), 6);
    assert!(h[5].0 < h[0].0, "training loss {:?}", h);
    assert_selected_on_validation(&model);
    let stored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(model.join("config.json")).unwrap()).unwrap();
    assert_eq!(stored["recipe"]["validation_rollout"], true);
    let _ = std::fs::remove_dir_all(&root);
}

/// `cargo xtask train altconv` on the quick `limb` dataset: a run split by `--resume`
/// ends bit for bit where an uninterrupted one does, the kept epoch is the best on
/// validation, and widths beyond any machine are refused by field before any allocation.
#[test]
fn train_altconv_resumes_bit_for_bit_and_refuses_absurd_widths() {
    let root = scratch("altconv");
    let data = root.join("data");
    let out = xtask(&["dataset", "limb", "--size", "quick", "--quiet"], &[("--out", &data)]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let config = root.join("config.json");
    std::fs::write(&config, r#"{"hidden": [8, 8], "steps": 4, "batch": 1}"#).unwrap();
    let run = |out: &Path, extra: &[&str]| {
        let mut a = vec!["train", "altconv", "--model", "alt", "--quiet"];
        a.extend_from_slice(extra);
        xtask(&a, &[("--data", &data), ("--config", &config), ("--out", out)])
    };
    let (straight, split) = (root.join("straight"), root.join("split"));
    for (dir, extra) in [
        (&straight, vec!["--epochs", "4", "--lr", "0.01"]),
        (&split, vec!["--epochs", "2", "--lr", "0.01"]),
        (&split, vec!["--epochs", "4", "--lr", "0.01", "--resume"]),
    ] {
        let o = run(dir, &extra);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    assert_eq!(history(&straight).len(), 4);
    assert_eq!(history(&straight), history(&split));
    for f in ["best/net/params.safetensors", "last/net/optimizer.safetensors"] {
        assert_eq!(
            std::fs::read(straight.join(f)).unwrap(),
            std::fs::read(split.join(f)).unwrap(),
            "{f}"
        );
    }
    assert_selected_on_validation(&straight);
    // --lr reached the configuration the model stores.
    let stored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(straight.join("config.json")).unwrap()).unwrap();
    assert_eq!(stored["adam"]["learning_rate"].as_f64(), Some(0.01));
    // The epoch lines are in the run's log.
    let log = std::fs::read_to_string(straight.join("train.log")).unwrap();
    assert_eq!(log.lines().filter(|l| l.contains("validation")).count(), 5);
    // The run's own scoring reads the validation split, never the test split.
    let scores: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(straight.join("scores.json")).unwrap()).unwrap();
    assert!(scores.get("test_rollout_mm").is_none());
    for m in ["skinning", "alt-convlstm"] {
        assert!(
            scores["validation_rollout_mm"][m].as_f64().is_some_and(f64::is_finite),
            "{scores}"
        );
    }
    // A width of four billion is a typo: refused by name, nothing allocated or written.
    std::fs::write(&config, r#"{"hidden": [8, 4000000000], "steps": 4}"#).unwrap();
    let bad = root.join("bad");
    let out = run(&bad, &[]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("hidden[1]"), "{err}");
    assert!(!bad.exists());
    for (json, field) in [
        (r#"{"steps": 0}"#, "`steps`"),
        (
            r#"{"adam": {"learning_rate": -1, "beta1": 0.9, "beta2": 0.999, "epsilon": 1e-8}}"#,
            "adam.learning_rate",
        ),
        (
            r#"{"schedule": {"decay": {"kind": "exponential", "per_epoch": 2}}}"#,
            "schedule.decay.per_epoch",
        ),
        (r#"{"stpes": 3}"#, "stpes"),
        (r#"{"hidden": [8, 8], "steps": 5000}"#, "set steps to at most"),
    ] {
        std::fs::write(&config, json).unwrap();
        let out = run(&bad, &[]);
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(field), "{json}: {err}");
        assert!(!bad.exists());
    }
    std::fs::write(&config, r#"{"hidden": [8, 8], "steps": 4}"#).unwrap();
    let out = run(&bad, &["--lr=1e9"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("adam.learning_rate"));
    assert!(!out.status.success() && !bad.exists());
    // A flipped byte in a sequence file is refused by name before anything trains.
    std::fs::write(&config, r#"{"hidden": [8, 8], "steps": 4, "batch": 1}"#).unwrap();
    let seq = std::fs::read_dir(&data)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "safetensors"))
        .unwrap();
    let mut bytes = std::fs::read(&seq).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 1;
    std::fs::write(&seq, bytes).unwrap();
    let out = run(&bad, &["--epochs", "1"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("SHA-256") && err.contains(seq.file_name().unwrap().to_str().unwrap()),
        "{err}"
    );
    assert!(!bad.exists());
    let _ = std::fs::remove_dir_all(&root);
}
