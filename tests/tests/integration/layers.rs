//! The crates' dependency arrows point down: every workspace member's Cargo.toml
//! (dependencies, build- and dev-dependencies) is checked against the layer order written
//! in docs/ARCHITECTURE.md (its `## Layers` block), so the document and the manifests
//! cannot drift apart. Also: `weft-testkit` is only ever a dev-dependency, and only
//! `weft-nn` depends on candle.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn read_toml(path: &Path) -> toml::Table {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    toml::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Each member's package name → its manifest, from the workspace's `members` (plain paths
/// and `dir/*` globs).
fn members() -> BTreeMap<String, toml::Table> {
    let workspace = read_toml(&root().join("Cargo.toml"));
    let patterns = workspace["workspace"]["members"].as_array().expect("workspace.members");
    let mut dirs = Vec::new();
    for pattern in patterns {
        let pattern = pattern.as_str().expect("a member is a path");
        match pattern.strip_suffix("/*") {
            Some(parent) => {
                for entry in std::fs::read_dir(root().join(parent)).expect("member directory") {
                    let dir = entry.expect("member directory entry").path();
                    if dir.join("Cargo.toml").is_file() {
                        dirs.push(dir);
                    }
                }
            }
            None => dirs.push(root().join(pattern)),
        }
    }
    dirs.iter()
        .map(|dir| {
            let manifest = read_toml(&dir.join("Cargo.toml"));
            let name = manifest["package"]["name"].as_str().expect("package.name").to_string();
            (name, manifest)
        })
        .collect()
}

/// The layer of each crate, 0 the lowest, read from the ```text block under
/// `## Layers` in docs/ARCHITECTURE.md (one line per layer, lowest first).
fn layers() -> BTreeMap<String, usize> {
    let doc = std::fs::read_to_string(root().join("docs/ARCHITECTURE.md")).expect("docs/ARCHITECTURE.md");
    let section = doc
        .split("\n## Layers\n")
        .nth(1)
        .expect("docs/ARCHITECTURE.md has a `## Layers` section");
    let block = section
        .split("```text\n")
        .nth(1)
        .and_then(|b| b.split("```").next())
        .expect("the `## Layers` section holds a ```text block");
    let mut layer_of = BTreeMap::new();
    for (layer, line) in block.lines().filter(|l| !l.trim().is_empty()).enumerate() {
        for name in line.split_whitespace() {
            assert!(
                layer_of.insert(name.to_string(), layer).is_none(),
                "{name} is in two layers"
            );
        }
    }
    layer_of
}

/// `(table, dependency package name)` for every dependency of a manifest, renames resolved.
fn dependencies(manifest: &toml::Table) -> Vec<(&'static str, String)> {
    let mut deps = Vec::new();
    for table in ["dependencies", "build-dependencies", "dev-dependencies"] {
        let Some(entries) = manifest.get(table).and_then(toml::Value::as_table) else {
            continue;
        };
        for (key, value) in entries {
            let name = value.get("package").and_then(toml::Value::as_str).unwrap_or(key);
            deps.push((table, name.to_string()));
        }
    }
    if let Some(targets) = manifest.get("target").and_then(toml::Value::as_table) {
        for spec in targets.values().filter_map(toml::Value::as_table) {
            deps.extend(dependencies(spec));
        }
    }
    deps
}

#[test]
fn every_member_sits_in_one_layer() {
    let members = members();
    let layers = layers();
    for name in members.keys() {
        assert!(
            layers.contains_key(name),
            "{name} is a workspace member missing from ARCHITECTURE.md's layers"
        );
    }
    for name in layers.keys() {
        assert!(
            members.contains_key(name),
            "ARCHITECTURE.md's layers name {name}, which is not a workspace member"
        );
    }
}

#[test]
fn dependencies_point_down_and_testkit_is_dev_only() {
    let members = members();
    let layers = layers();
    let mut upward = Vec::new();
    for (name, manifest) in &members {
        let own = layers[name];
        for (table, dep) in dependencies(manifest) {
            let Some(&theirs) = layers.get(&dep) else {
                continue; // not a workspace crate
            };
            if dep == "weft-testkit" {
                if table != "dev-dependencies" {
                    upward.push(format!(
                        "{name} has weft-testkit in [{table}]: it is a dev-dependency only"
                    ));
                }
            } else if theirs >= own {
                upward.push(format!(
                    "{name} (layer {own}) depends on {dep} (layer {theirs}) in [{table}]"
                ));
            }
        }
    }
    assert!(
        upward.is_empty(),
        "arrows that do not point down:\n{}",
        upward.join("\n")
    );
}

#[test]
fn only_weft_nn_depends_on_candle() {
    for (name, manifest) in members() {
        if name == "weft-nn" {
            continue;
        }
        for (table, dep) in dependencies(&manifest) {
            assert!(
                !dep.starts_with("candle"),
                "{name} depends on {dep} in [{table}]: only weft-nn touches candle"
            );
        }
    }
}

/// The crates whose invariant in docs/ARCHITECTURE.md is "no candle" although the layer
/// order alone would let them reach it: weft-py sits on the top layer beside xtask, and
/// weft-surrogate exists so that the guard's surrogates load without candle.
const CANDLE_FREE: [&str; 2] = ["weft-surrogate", "weft-py"];

#[test]
fn the_candle_free_crates_reach_neither_candle_nor_weft_nn_through_other_crates() {
    let members = members();
    for name in CANDLE_FREE {
        // Normal dependencies only, followed through workspace members.
        let (mut seen, mut todo) = (
            std::collections::BTreeSet::new(),
            vec![(name.to_string(), name.to_string())],
        );
        while let Some((crate_name, path)) = todo.pop() {
            let manifest = &members[&crate_name];
            for (table, dep) in dependencies(manifest) {
                if table != "dependencies" || !seen.insert(dep.clone()) {
                    continue;
                }
                let path = format!("{path} → {dep}");
                assert!(
                    dep != "weft-nn" && !dep.starts_with("candle"),
                    "{path}: {name} must not depend on candle (docs/ARCHITECTURE.md)"
                );
                if members.contains_key(&dep) {
                    todo.push((dep, path));
                }
            }
        }
    }
}
