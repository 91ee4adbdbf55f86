//! Dataset generation is deterministic, resumable after a kill, and shardable: an
//! interrupted run resumed with `--resume`, and three shards merged, give files
//! byte-identical to one uninterrupted run.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const XTASK: &str = env!("CARGO_BIN_EXE_xtask");

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("weft-dataset-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// `dataset sheet-ms --size quick` with enough frames that a run takes a few seconds.
fn dataset(out: &Path, extra: &[&str]) -> Command {
    let mut c = Command::new(XTASK);
    c.args([
        "dataset",
        "sheet-ms",
        "--size",
        "quick",
        "--sequences",
        "6",
        "--frames",
        "300",
        "--quiet",
    ])
    .arg("--out")
    .arg(out)
    .args(extra)
    .stdout(Stdio::null())
    .stderr(Stdio::null());
    c
}

fn run_ok(mut c: Command) {
    let status = c.status().expect("xtask runs");
    assert!(status.success(), "{c:?} failed: {status}");
}

fn manifest(dir: &Path, name: &str) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join(name)).unwrap()).unwrap()
}

/// Every file the reference manifest lists, and the manifest itself, byte for byte.
fn assert_same_dataset(reference: &Path, other: &Path) {
    let m = manifest(reference, "manifest.json");
    let mut files = vec!["manifest.json".to_string()];
    files.extend(
        m["files"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| f["path"].as_str().unwrap().to_string()),
    );
    files.extend(
        m["sequences"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["path"].as_str().unwrap().to_string()),
    );
    assert_eq!(files.len(), 1 + 2 + 6);
    for f in files {
        let a = std::fs::read(reference.join(&f)).unwrap();
        let b = std::fs::read(other.join(&f)).unwrap_or_else(|e| panic!("{f} missing in {}: {e}", other.display()));
        assert!(
            a == b,
            "{f} differs between {} and {}",
            reference.display(),
            other.display()
        );
    }
}

#[test]
fn killed_run_resumed_and_merged_shards_match_an_uninterrupted_run() {
    let full = scratch("full");
    run_ok(dataset(&full, &[]));

    // Kill a second run as soon as its first sequence is recorded in the manifest.
    let killed = scratch("killed");
    let mut child = dataset(&killed, &[]).spawn().unwrap();
    let start = Instant::now();
    while !killed.join("manifest.json").exists() {
        assert!(start.elapsed() < Duration::from_secs(120), "no sequence written");
        std::thread::sleep(Duration::from_millis(1));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let partial = manifest(&killed, "manifest.json");
    let done = partial["sequences"].as_array().unwrap().len();
    assert!(
        (1..6).contains(&done),
        "the kill should interrupt the run, {done} of 6 sequences done"
    );
    // Without --resume the directory is not silently overwritten.
    let status = dataset(&killed, &[]).status().unwrap();
    assert!(
        !status.success(),
        "re-running into a started dataset without --resume must fail"
    );
    run_ok(dataset(&killed, &["--resume"]));
    assert_same_dataset(&full, &killed);

    // Three shards, two in one directory and one in another, merged.
    let shards_a = scratch("shards-a");
    let shards_b = scratch("shards-b");
    run_ok(dataset(&shards_a, &["--shard", "0/3"]));
    run_ok(dataset(&shards_a, &["--shard", "2/3"]));
    run_ok(dataset(&shards_b, &["--shard", "1/3"]));
    let merged = scratch("merged");
    let mut merge = Command::new(XTASK);
    merge
        .args(["dataset", "merge", "--out"])
        .arg(&merged)
        .arg(&shards_a)
        .arg(&shards_b);
    run_ok(merge);
    assert_same_dataset(&full, &merged);

    // A corrupted shard file is caught by merge.
    let seq = manifest(&shards_b, "manifest-shard-1-of-3.json")["sequences"][0]["path"]
        .as_str()
        .unwrap()
        .to_string();
    let mut bytes = std::fs::read(shards_b.join(&seq)).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 1;
    std::fs::write(shards_b.join(&seq), bytes).unwrap();
    let out = Command::new(XTASK)
        .args(["dataset", "merge", "--out"])
        .arg(scratch("merged-bad"))
        .arg(&shards_a)
        .arg(&shards_b)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("SHA-256") && err.contains(&seq), "{err}");

    for d in [full, killed, shards_a, shards_b, merged] {
        let _ = std::fs::remove_dir_all(d);
    }
}

#[test]
fn nnwarp_dataset_registers_every_linear_frame_to_three_materials() {
    let out = scratch("nnwarp");
    let status = Command::new(XTASK)
        .args(["dataset", "nnwarp", "--size", "quick", "--quiet", "--out"])
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let m = manifest(&out, "manifest.json");
    let files: Vec<&str> = m["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["path"].as_str().unwrap())
        .collect();
    assert_eq!(files, ["scene.toml", "rest.node", "rest.ele"]);
    let body = weft_mesh::io::read_tetgen(&out.join("rest.node")).unwrap();
    // The training beam scaled into the unit sphere.
    let radius = body.positions().iter().map(|p| p.norm()).fold(0.0, f64::max);
    assert!((radius - 1.0).abs() < 1e-9, "{radius}");
    let v = body.num_vertices();
    let mut splits = Vec::new();
    for (i, s) in m["sequences"].as_array().unwrap().iter().enumerate() {
        assert!(s["error"].is_null(), "{s}");
        splits.push(s["split"].as_str().unwrap().to_string());
        let bytes = std::fs::read(out.join(s["path"].as_str().unwrap())).unwrap();
        let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        let f = s["frames"].as_u64().unwrap() as usize;
        for key in ["linear", "co-rotational", "stvk", "neo-hookean"] {
            assert_eq!(st.tensor(key).unwrap().shape(), &[f, v, 3], "{key}");
        }
        let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
        let meta = meta.metadata().as_ref().unwrap();
        let field: serde_json::Value = serde_json::from_str(&meta["field"]).unwrap();
        assert_eq!(field["kind"], if i % 4 == 3 { "circular" } else { "directional" });
        let nu: f64 = meta["poisson"].parse().unwrap();
        assert!((0.2..=0.45).contains(&nu));
    }
    assert!(splits.contains(&"train".to_string()) && splits.contains(&"test".to_string()));
}

/// A quick dataset `name` of `count` sequences, generated whole, then with a damaged
/// sequence resumed, then as two merged shards: every sequence and the shared files
/// (`shared`, beside the manifest) byte-identical.
fn resumes_and_merges_byte_identically(name: &str, count: usize, shared: &[&str]) {
    let run = |out: &Path, extra: &[&str]| {
        let mut c = Command::new(XTASK);
        c.args(["dataset", name, "--size", "quick", "--quiet", "--out"])
            .arg(out)
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        run_ok(c);
    };
    let full = scratch(&format!("{name}-full"));
    run(&full, &[]);
    let m = manifest(&full, "manifest.json");
    assert_eq!(m["dataset"], name);
    let sequences: Vec<String> = m["sequences"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["path"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(sequences.len(), count);
    let same = |other: &Path| {
        for f in sequences
            .iter()
            .map(String::as_str)
            .chain(["manifest.json", "scene.toml"])
            .chain(shared.iter().copied())
        {
            assert!(
                std::fs::read(full.join(f)).unwrap() == std::fs::read(other.join(f)).unwrap(),
                "{f} differs in {}",
                other.display()
            );
        }
    };
    // A damaged sequence is found by its checksum and recomputed by --resume.
    let damaged = scratch(&format!("{name}-damaged"));
    std::fs::create_dir_all(&damaged).unwrap();
    for entry in std::fs::read_dir(&full).unwrap() {
        let p = entry.unwrap().path();
        std::fs::copy(&p, damaged.join(p.file_name().unwrap())).unwrap();
    }
    let mut bytes = std::fs::read(damaged.join(&sequences[2])).unwrap();
    let k = bytes.len() / 2;
    bytes[k] ^= 0x10;
    std::fs::write(damaged.join(&sequences[2]), bytes).unwrap();
    run(&damaged, &["--resume"]);
    same(&damaged);
    // Two shards merged.
    let (a, b) = (scratch(&format!("{name}-shard-a")), scratch(&format!("{name}-shard-b")));
    run(&a, &["--shard", "0/2"]);
    run(&b, &["--shard", "1/2"]);
    let merged = scratch(&format!("{name}-merged"));
    let mut merge = Command::new(XTASK);
    merge.args(["dataset", "merge", "--out"]).arg(&merged).arg(&a).arg(&b);
    run_ok(merge);
    same(&merged);
    // The shards' timings are joined: the evaluation reads the ground truth's cost there.
    let timing = manifest(&merged, "timing.json");
    assert_eq!(timing["sequences"].as_object().unwrap().len(), count);
}

#[test]
fn the_jiggling_limb_dataset_resumes_and_merges_byte_identically() {
    resumes_and_merges_byte_identically("limb-jiggle", 4, &[]);
}

#[test]
fn the_loose_drape_dataset_resumes_and_merges_byte_identically() {
    // The settle steps and the parallel solves of a chunk must not depend on timing or
    // thread count; the scene's parameters and rest meshes are rewritten identically.
    resumes_and_merges_byte_identically("drape-loose", 6, &["drape.json", "sleeve.obj", "body.obj"]);
}
