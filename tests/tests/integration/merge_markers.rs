//! No source or document holds a merge's conflict markers: a merge committed with its
//! conflict unresolved once left both sides of a paragraph in docs/ARCHITECTURE.md, and
//! neither the compiler nor any other test reads a document's prose.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The `.rs`, `.md`, `.toml` and `.py` files under `dir`, skipping build output.
fn text_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().to_string();
        if path.is_dir() {
            if !matches!(name.as_str(), "target" | ".git" | "node_modules") && !name.starts_with('.') {
                text_files(&path, out);
            }
        } else if ["rs", "md", "toml", "py"]
            .iter()
            .any(|e| path.extension().is_some_and(|x| x == *e))
        {
            out.push(path);
        }
    }
}

/// The lines of `text` that open, separate or close a conflict.
fn markers(text: &str) -> Vec<usize> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with("<<<<<<< ") || l.starts_with(">>>>>>> ") || *l == "=======")
        .map(|(i, _)| i + 1)
        .collect()
}

#[test]
fn no_file_holds_a_conflict_marker() {
    assert_eq!(
        markers("a\n<<<<<<< HEAD\nb\n=======\nc\n>>>>>>> other\n"),
        vec![2, 4, 6]
    );
    let mut files = Vec::new();
    for dir in ["crates", "docs", "xtask", "tests", "benches", "fixtures"] {
        text_files(&root().join(dir), &mut files);
    }
    files.push(root().join("README.md"));
    assert!(files.len() > 100, "only {} files read", files.len());
    let found: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let lines = markers(&std::fs::read_to_string(f).ok()?);
            (!lines.is_empty()).then(|| format!("{}: lines {lines:?}", f.display()))
        })
        .collect();
    assert!(found.is_empty(), "conflict markers:\n{}", found.join("\n"));
}
