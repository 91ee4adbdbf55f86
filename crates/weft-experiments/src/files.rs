//! File helpers every module of the crate may use: the bottom layer, importing nothing of
//! the crate but its error type.
//!
//! What is not here: the dataset and record formats and their writers (weft-data's
//! `files`), caches of an experiment's own results (the experiment).

use std::path::Path;

use crate::error::Context;

/// Copies the directory `from` into `to`, recursively (made if missing).
pub fn copy_tree(from: &Path, to: &Path) -> crate::Result<()> {
    std::fs::create_dir_all(to)?;
    for e in std::fs::read_dir(from).with_context(|| format!("reading {}", from.display()))? {
        let p = e?.path();
        let target = to.join(p.file_name().context("unnamed file")?);
        if p.is_dir() {
            copy_tree(&p, &target)?;
        } else {
            std::fs::copy(&p, &target)?;
        }
    }
    Ok(())
}
