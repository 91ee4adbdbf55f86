//! The command line as a shell user meets it: a reader that stops early (`cargo xtask mesh
//! info F | head -1`) ends the command quietly, not with a panic, and a negative number
//! given to an option reaches that option's own check.

use std::process::{Command, Stdio};

const XTASK: &str = env!("CARGO_BIN_EXE_xtask");

#[test]
fn a_closed_pipe_ends_the_command_quietly() {
    let dir = std::env::temp_dir().join(format!("weft-output-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mesh = dir.join("s.ply");
    let made = Command::new(XTASK)
        .args(["mesh", "sheet", "--n", "4", "--out"])
        .arg(&mesh)
        .output()
        .unwrap();
    assert!(made.status.success(), "{}", String::from_utf8_lossy(&made.stderr));
    // The reading end is closed before the command starts: its first line hits a
    // broken pipe.
    let (reader, writer) = std::io::pipe().unwrap();
    drop(reader);
    let out = Command::new(XTASK)
        .args(["mesh", "info"])
        .arg(&mesh)
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    // The same command into an open pipe prints the whole report.
    let full = Command::new(XTASK).args(["mesh", "info"]).arg(&mesh).output().unwrap();
    assert!(full.status.success());
    let report: serde_json::Value = serde_json::from_slice(&full.stdout).unwrap();
    assert_eq!(report["vertices"], 16);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_negative_number_reaches_the_options_own_check() {
    let dir = std::env::temp_dir().join(format!("weft-negative-test-{}", std::process::id()));
    let out = dir.join("t.vtk");
    let run = |args: &[&str]| {
        Command::new(XTASK)
            .args(args)
            .env("RUST_BACKTRACE", "0")
            .output()
            .unwrap()
    };
    // A range check in the library names the value.
    let e = run(&[
        "mesh",
        "tapered-beam",
        "--tip-scale",
        "-0.5",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&e.stderr);
    assert!(!e.status.success());
    assert!(
        stderr.contains("tip scale must be positive") && stderr.contains("-0.5"),
        "{stderr}"
    );
    // An unsigned count: clap's own parse error names the option and the value.
    let e = run(&["simulate", "sheet-ms", "--frames", "-3", "--out", dir.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&e.stderr);
    assert!(stderr.contains("invalid value '-3' for '--frames"), "{stderr}");
    assert!(
        !stderr.contains("-- -3"),
        "no advice to pass the value positionally: {stderr}"
    );
    assert!(!out.exists() && !dir.exists(), "nothing written");
}
