//! `evaluate` writes a report that `check-report` accepts, and `check-report` rejects a
//! report whose records lose a field or carry a non-finite number.

use std::path::PathBuf;
use std::process::Command;

const XTASK: &str = env!("CARGO_BIN_EXE_xtask");

fn check(dir: &PathBuf) -> (bool, String) {
    let out = Command::new(XTASK).arg("check-report").arg(dir).output().unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn quick_projection_evaluation_passes_the_report_check_and_tampering_fails_it() {
    let dir = std::env::temp_dir().join(format!("weft-report-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let status = Command::new(XTASK)
        .args(["evaluate", "--quick", "--only", "proj", "--quiet", "--out"])
        .arg(&dir)
        .status()
        .unwrap();
    assert!(status.success());
    let (ok, err) = check(&dir);
    assert!(ok, "{err}");

    let results = dir.join("results.json");
    let original = std::fs::read_to_string(&results).unwrap();
    let mut records: Vec<serde_json::Value> = serde_json::from_str(&original).unwrap();
    assert!(
        records
            .iter()
            .any(|r| r["method"] == "ipm" && r["metric"] == "forward-seconds")
    );
    records[0].as_object_mut().unwrap().remove("paper_value");
    std::fs::write(&results, serde_json::to_string(&records).unwrap()).unwrap();
    let (ok, err) = check(&dir);
    assert!(!ok && err.contains("paper_value"), "{err}");

    // JSON has no NaN, so a broken writer would emit null for a value.
    let mut records: Vec<serde_json::Value> = serde_json::from_str(&original).unwrap();
    records[1]["value"] = serde_json::Value::Null;
    std::fs::write(&results, serde_json::to_string(&records).unwrap()).unwrap();
    assert!(!check(&dir).0);

    // The page opens with the claims; a report whose page misses an experiment the
    // records hold fails.
    std::fs::write(&results, &original).unwrap();
    let page = dir.join("index.html");
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(html.contains("id=\"claims\"") && html.contains("id=\"experiment-proj\""));
    std::fs::write(&page, html.replace("id=\"experiment-proj\"", "id=\"other\"")).unwrap();
    let (ok, err) = check(&dir);
    assert!(!ok && err.contains("\"proj\""), "{err}");
    std::fs::write(&page, &html).unwrap();

    // A second run resumes: the cached experiment is reused, not recomputed.
    std::fs::write(&results, &original).unwrap();
    let out = Command::new(XTASK)
        .args(["evaluate", "--quick", "--only", "proj", "--quiet", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("reusing"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Publishing one experiment rebuilds the whole published report: the experiments
/// published before are taken from its committed outputs, and the page and records hold
/// them all.
#[test]
fn republishing_one_experiment_keeps_the_others() {
    let root = std::env::temp_dir().join(format!("weft-publish-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    let dest = root.join("published");
    // A build of uncommitted code may not publish (CI builds a clean clone and runs the
    // rest of this test; a developer's dirty tree checks the refusal instead).
    let version = Command::new(XTASK).arg("--version").output().unwrap();
    if String::from_utf8_lossy(&version.stdout).contains("-dirty") {
        let o = Command::new(XTASK)
            .args(["evaluate", "--quick", "--quiet", "--only", "proj", "--out"])
            .arg(root.join("a"))
            .arg("--publish")
            .arg(&dest)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains("uncommitted"), "{err}");
        assert!(
            !root.join("a").join("experiments").join("proj.json").exists(),
            "it ran before refusing"
        );
        return;
    }
    for (only, out) in [("proj", "a"), ("sim", "b")] {
        let o = Command::new(XTASK)
            .args(["evaluate", "--quick", "--quiet", "--only", only, "--out"])
            .arg(root.join(out))
            .arg("--publish")
            .arg(&dest)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let records: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(dest.join("results.json")).unwrap()).unwrap();
    for e in ["proj", "sim"] {
        assert!(records.iter().any(|r| r["experiment"] == e), "{e} missing");
        assert!(dest.join("experiments").join(format!("{e}.json")).exists());
    }
    let provenance = std::fs::read_to_string(dest.join("PROVENANCE.md")).unwrap();
    assert!(
        provenance.contains("taken from the report published here before"),
        "{provenance}"
    );
    let out = Command::new(XTASK)
        .args(["check-report", "--published"])
        .arg(&dest)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let _ = std::fs::remove_dir_all(&root);
}

/// The committed report in `docs/results` passes the check as a published report (its
/// predictions are not committed), and fails the full check for exactly that reason.
#[test]
fn the_published_report_passes_the_published_check() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/results");
    let out = Command::new(XTASK)
        .args(["check-report", "--published"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (ok, err) = check(&dir);
    assert!(!ok && err.contains("predictions"), "{err}");
}
