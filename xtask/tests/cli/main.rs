//! xtask's command line end to end, as one test binary (one link for the crate): each
//! module drives the built `xtask` binary through one command family.

mod acap;
mod dataset;
mod diagnostics;
mod embed_diagnostics;
mod guard;
mod newcomer;
mod pipes;
mod report;
mod score;
mod train;

use std::path::Path;
use std::process::{Command, Output};

/// Runs the built `xtask` with `args`.
pub fn xtask(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_xtask"))
        .args(args)
        .output()
        .expect("xtask runs")
}

/// Runs `xtask` with `args`, which must succeed; returns its stderr, where commands say
/// what they did.
pub fn xtask_ok(args: &[&str]) -> String {
    let out = xtask(args);
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "{args:?}: {stderr}");
    stderr
}

/// A path as a command-line argument.
pub fn arg(p: &Path) -> &str {
    p.to_str().expect("a UTF-8 path")
}
