//! Records the code version at build time, so that a binary copied elsewhere (a long job
//! runs a copy while the checkout moves on) still names the commit it was built from.
//! `git describe` at run time would name whatever the checkout holds by then.

use std::path::Path;
use std::process::Command;

fn git(root: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).current_dir(root).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
        .filter(|s| !s.is_empty())
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    // Rebuild the version whenever the commit, the index or any source the binary is built
    // from changes (the last makes `-dirty` right for uncommitted edits).
    for dir in ["crates", "xtask/src", "Cargo.toml", "Cargo.lock"] {
        println!("cargo:rerun-if-changed=../{dir}");
    }
    if let Some(git_dir) = git(&root, &["rev-parse", "--absolute-git-dir"]) {
        let mut watch = vec!["HEAD".to_string(), "index".to_string(), "packed-refs".to_string()];
        watch.extend(git(&root, &["symbolic-ref", "-q", "HEAD"]));
        // A missing file would make cargo rerun this script on every build.
        for f in watch.iter().filter(|f| Path::new(&git_dir).join(f).exists()) {
            println!("cargo:rerun-if-changed={git_dir}/{f}");
        }
    }
    let version = match git(&root, &["describe", "--always", "--dirty", "--abbrev=12"]) {
        Some(g) => format!("{} ({g})", env!("CARGO_PKG_VERSION")),
        None => env!("CARGO_PKG_VERSION").to_string(),
    };
    println!("cargo:rustc-env=WEFT_CODE_VERSION={version}");
}
