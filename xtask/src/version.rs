//! The code version a run records. A leaf module: it imports nothing of xtask.

/// The code version recorded in manifests and results: the crate version and, when built
/// from a git checkout, the commit (with `-dirty` for uncommitted changes). Fixed at build
/// time by `build.rs`, so it names the code this binary runs.
pub fn code_version() -> String {
    env!("WEFT_CODE_VERSION").to_string()
}
