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
