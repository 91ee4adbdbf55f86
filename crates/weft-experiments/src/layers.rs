//! The crate's layers, and a test that no module imports from a layer above its own; and a
//! test that no function is longer than [`LONGEST_FUNCTION`] lines (issue 68: functions
//! short enough to read at once).
//!
//! Every `crate::…` and `super::…` path in `src/**/*.rs` (outside comments) is resolved to
//! the module it names and checked against [`LAYERS`]: a module may use its own entry
//! (the files of one experiment use each other) and the entries of lower rank, never one
//! of the same rank or above. What is not checked: paths to other crates (Cargo's
//! dependency graph orders those) and macros' `$crate`.

use std::path::Path;

/// `(module path prefix, rank)`: a module belongs to the entry with the longest prefix of
/// its path. Lower ranks are imported from, higher ones import.
const LAYERS: &[(&str, u8)] = &[
    // The bottom: errors, then the file helpers everything may use.
    ("error", 0),
    ("files", 1),
    // Records, and what formats them: the papers' tables and the renders.
    ("records", 2),
    ("paper", 3),
    ("render", 3),
    // The report, rebuilt from records.
    ("report", 4),
    // What the experiments share: their context, training progress, the study helper.
    ("evaluate::context", 5),
    ("progress", 6),
    ("evaluate::study", 7),
    // The experiments, each independent of the others.
    ("evaluate::sim", 8),
    ("evaluate::proj", 8),
    ("evaluate::embed", 8),
    ("evaluate::nnwarp", 8),
    ("evaluate::altconv", 8),
    ("evaluate::drape", 8),
    ("stability", 8),
    // The runner and scoring, which dispatch to the experiments.
    ("evaluate", 9),
    ("score", 9),
    // The crate root, which declares every module (and `layers`, this test).
    ("", 10),
    ("layers", 10),
];

/// The entry of `module` (a path like `evaluate::drape::scoring`): its prefix and rank.
fn layer_of(module: &str) -> (&'static str, u8) {
    let matches = |prefix: &str| prefix.is_empty() || module == prefix || module.starts_with(&format!("{prefix}::"));
    LAYERS
        .iter()
        .filter(|(p, _)| matches(p))
        .max_by_key(|(p, _)| p.len())
        .copied()
        .unwrap_or(("", 10))
}

/// The module path of a source file relative to `src/`: `lib.rs` is the root,
/// `a/mod.rs` is `a`, `a/b.rs` is `a::b`.
fn module_of(relative: &Path) -> String {
    let mut parts: Vec<String> = relative
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts.join("::")
}

/// Items the crate root re-exports from `error`.
const ROOT_ERROR_ITEMS: [&str; 3] = ["Result", "Error", "Context"];

/// The module a path names, from the module it is written in: `crate::a::b::Item` and
/// `super::b::Item` (in `a::c`) both name `a::b::Item`, which [`layer_of`] places.
fn resolve(module: &str, root: &str, rest: &[&str]) -> String {
    let mut base: Vec<&str> = if root == "crate" {
        Vec::new()
    } else {
        module.split("::").filter(|s| !s.is_empty()).collect()
    };
    let mut rest = rest;
    if root == "super" {
        base.pop();
        while rest.first() == Some(&"super") {
            base.pop();
            rest = &rest[1..];
        }
    }
    if base.is_empty() && rest.first().is_some_and(|r| ROOT_ERROR_ITEMS.contains(r)) {
        return "error".into();
    }
    base.extend(rest);
    base.join("::")
}

/// `text` with comments and the contents of string and character literals blanked
/// (newlines kept, so line numbers hold): what is left is the code the compiler resolves.
fn code_only(text: &str) -> String {
    let chars: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    let blank = |c: char| if c == '\n' { '\n' } else { ' ' };
    while i < chars.len() {
        let c = chars[i];
        let next = chars.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < chars.len() && chars[i] != '\n' {
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            while i < chars.len() && !(chars[i] == '*' && chars.get(i + 1) == Some(&'/')) {
                out.push(blank(chars[i]));
                i += 1;
            }
            i += 2;
        } else if c == '"' || (c == 'r' && matches!(next, Some('"' | '#')) && !ident_before(&chars, i)) {
            // A string, raw (`r"…"`, `r#"…"#`) or not.
            let raw = c == 'r';
            let mut hashes = 0;
            i += 1;
            while raw && chars.get(i) == Some(&'#') {
                hashes += 1;
                i += 1;
            }
            i += usize::from(raw);
            out.push('"');
            while i < chars.len() {
                if !raw && chars[i] == '\\' {
                    out.push(' ');
                    out.push(blank(chars.get(i + 1).copied().unwrap_or(' ')));
                    i += 2;
                    continue;
                }
                if chars[i] == '"' && (0..hashes).all(|k| chars.get(i + 1 + k) == Some(&'#')) {
                    i += 1 + hashes;
                    break;
                }
                out.push(blank(chars[i]));
                i += 1;
            }
            out.push('"');
        } else if c == '\'' && (next == Some('\\') || chars.get(i + 2) == Some(&'\'')) {
            // A character literal (not a lifetime): `'x'`, `'\n'`, `'\''`.
            i += if next == Some('\\') { 3 } else { 2 };
            while i < chars.len() && chars[i] != '\'' {
                i += 1;
            }
            i += 1;
            out.push_str("' '");
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

/// Whether the character before `i` continues an identifier (so an `r` there is not a raw
/// string's prefix).
fn ident_before(chars: &[char], i: usize) -> bool {
    i > 0 && (chars[i - 1].is_alphanumeric() || chars[i - 1] == '_')
}

/// Every `crate::…`/`super::…` path in `text`, the source of `module`, as (line, path
/// written, module it names). Comments and literals are skipped; inside an inline module
/// (`mod tests { … }` at a file's end), `super` is the file's own module.
fn imports(module: &str, text: &str) -> Vec<(usize, String, String)> {
    let mut found = Vec::new();
    let mut inline = false;
    for (n, code) in code_only(text).lines().enumerate() {
        let trimmed = code.trim_start();
        if trimmed.starts_with("mod ") || trimmed.starts_with("pub mod ") || trimmed.starts_with("pub(crate) mod ") {
            inline |= trimmed.trim_end().ends_with('{');
        }
        // Inside an inline module, `super` is one level deeper than the file's module.
        let here = if inline {
            format!("{module}::inline")
        } else {
            module.to_string()
        };
        for (written, root, rest) in paths(code) {
            let rest: Vec<&str> = rest.iter().map(String::as_str).collect();
            found.push((n + 1, written, resolve(&here, &root, &rest)));
        }
    }
    found
}

/// The paths in one line of code, each as (text, `crate` or `super`, the segments after
/// it), with `use crate::{a::B, c}` expanded into one path per leaf.
fn paths(code: &str) -> Vec<(String, String, Vec<String>)> {
    let mut out = Vec::new();
    let bytes = code.as_bytes();
    let mut i = 0;
    while i < code.len() {
        let at_word_start =
            i == 0 || !(bytes[i - 1].is_ascii_alphanumeric() || bytes[i - 1] == b'_' || bytes[i - 1] == b'$');
        let root = ["crate::", "super::"].into_iter().find(|r| code[i..].starts_with(r));
        match root {
            Some(r) if at_word_start => {
                let start = i;
                i += r.len();
                let (segments, end) = segments(code, i);
                for s in segments {
                    out.push((code[start..end].to_string(), r.trim_end_matches("::").to_string(), s));
                }
                i = end.max(i);
            }
            _ => i += code[i..].chars().next().map_or(1, char::len_utf8),
        }
    }
    out
}

/// The segment lists of the path starting at byte `i` of `code` (after its root), one per
/// leaf of a `{…}` group, and the byte where the path ends.
fn segments(code: &str, mut i: usize) -> (Vec<Vec<String>>, usize) {
    let ident = |i: usize| {
        let len = code[i..]
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(code.len() - i);
        (code[i..i + len].to_string(), i + len)
    };
    let mut prefix = Vec::new();
    loop {
        if code[i..].starts_with('{') {
            // A group: split its top-level items and expand each.
            let mut depth = 0;
            let mut items = Vec::new();
            let mut item_start = i + 1;
            let mut end = code.len();
            for (k, c) in code[i..].char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' => {
                        depth -= 1;
                        if depth == 0 {
                            items.push(&code[item_start..i + k]);
                            end = i + k + 1;
                            break;
                        }
                    }
                    ',' if depth == 1 => {
                        items.push(&code[item_start..i + k]);
                        item_start = i + k + 1;
                    }
                    _ => {}
                }
            }
            let mut all = Vec::new();
            for item in items.iter().map(|s| s.trim()).filter(|s| !s.is_empty()) {
                let (leaves, _) = segments(item, 0);
                for leaf in leaves {
                    all.push(prefix.iter().cloned().chain(leaf).collect());
                }
            }
            return (all, end);
        }
        let (name, next) = ident(i);
        if name.is_empty() {
            return (vec![prefix], i);
        }
        prefix.push(name);
        if code[next..].starts_with("::") {
            i = next + 2;
        } else {
            return (vec![prefix], next);
        }
    }
}

/// The imports of `module` (source `text`) that go up: to another entry of the same rank
/// or above.
fn upward(module: &str, text: &str) -> Vec<String> {
    let (own, rank) = layer_of(module);
    imports(module, text)
        .into_iter()
        .filter_map(|(line, written, target)| {
            let (entry, target_rank) = layer_of(&target);
            (entry != own && target_rank >= rank)
                .then(|| format!("{module} (line {line}): `{written}` names {target} (rank {target_rank} ≥ {rank})"))
        })
        .collect()
}

fn sources(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            sources(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The most lines a function (signature to closing brace, tests included) may take.
const LONGEST_FUNCTION: usize = 150;

/// Every function with a body in `text`: (line of `fn`, name, lines from `fn` to its
/// closing brace). Comments and literals are blanked first, so braces in them do not count.
fn function_lengths(text: &str) -> Vec<(usize, String, usize)> {
    let code: Vec<char> = code_only(text).chars().collect();
    let line_at = |i: usize| code[..i].iter().filter(|&&c| c == '\n').count() + 1;
    let mut found = Vec::new();
    let mut i = 0;
    while i + 3 <= code.len() {
        let is_fn = code[i..].starts_with(&['f', 'n', ' ']) && !ident_before(&code, i);
        if !is_fn {
            i += 1;
            continue;
        }
        let name: String = code[i + 3..]
            .iter()
            .skip_while(|c| c.is_whitespace())
            .take_while(|c| c.is_alphanumeric() || **c == '_')
            .collect();
        // The body opens at the first `{` before any `;` (a declaration has no body).
        let Some(open) = (i..code.len()).find(|&j| code[j] == '{' || code[j] == ';') else {
            break;
        };
        if code[open] == ';' {
            i = open + 1;
            continue;
        }
        let mut depth = 0usize;
        let mut close = open;
        for (j, &c) in code.iter().enumerate().skip(open) {
            match c {
                '{' => depth += 1,
                '}' => depth -= 1,
                _ => {}
            }
            if depth == 0 {
                close = j;
                break;
            }
        }
        found.push((line_at(i), name, line_at(close) - line_at(i) + 1));
        // Nested functions are measured too: carry on inside the body.
        i = open + 1;
    }
    found
}

#[test]
fn no_function_is_longer_than_the_limit() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    let mut long = Vec::new();
    for f in &files {
        for (line, name, lines) in function_lengths(&std::fs::read_to_string(f).unwrap()) {
            if lines > LONGEST_FUNCTION {
                long.push(format!(
                    "{}:{line} `{name}`: {lines} lines",
                    f.strip_prefix(&src).unwrap().display()
                ));
            }
        }
    }
    assert!(
        long.is_empty(),
        "functions over {LONGEST_FUNCTION} lines:\n{}",
        long.join("\n")
    );
}

#[test]
fn a_function_is_measured_from_fn_to_its_closing_brace_past_braces_in_literals() {
    let text = "trait T {\n    fn declared(&self);\n}\n\nfn outer() {\n    let s = \"}}{\"; // }\n    fn inner() {\n    }\n    let c = '{';\n}\n";
    let found = function_lengths(text);
    assert_eq!(
        found,
        vec![(5, "outer".to_string(), 6), (7, "inner".to_string(), 2)],
        "{found:?}"
    );
}

#[test]
fn no_module_imports_from_a_layer_above_its_own() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    assert!(
        files.len() > 10,
        "found only {} sources under {}",
        files.len(),
        src.display()
    );
    let mut bad = Vec::new();
    for f in &files {
        let module = module_of(f.strip_prefix(&src).unwrap());
        bad.extend(upward(&module, &std::fs::read_to_string(f).unwrap()));
    }
    assert!(bad.is_empty(), "imports that go up a layer:\n{}", bad.join("\n"));
}

#[test]
fn the_check_reads_paths_as_the_compiler_does_and_catches_an_upward_one() {
    assert_eq!(module_of(Path::new("evaluate/drape/mod.rs")), "evaluate::drape");
    assert_eq!(
        module_of(Path::new("evaluate/drape/scoring.rs")),
        "evaluate::drape::scoring"
    );
    assert_eq!(module_of(Path::new("lib.rs")), "");
    // The call that once ran up from an experiment to the runner.
    let old = "fn share() -> crate::Result<()> {\n    super::copy_tree(&run, &to)?;\n}\n";
    let bad = upward("evaluate::embed", old);
    assert_eq!(bad.len(), 1, "{bad:?}");
    assert!(
        bad[0].contains("`super::copy_tree`") && bad[0].contains("names evaluate::copy_tree"),
        "{bad:?}"
    );
    // The same helper from the bottom module, the error type, a sibling file of the same
    // experiment, and a test module's `super::*` go down or sideways within an entry.
    let good = "use crate::files::copy_tree;\nuse crate::{Result, error::ensure};\nuse super::Garment;\n\
                // super::copy_tree in a comment\n#[cfg(test)]\nmod tests {\n    use super::*;\n}\n";
    assert_eq!(upward("evaluate::drape::studies", good), Vec::<String>::new());
    // Paths in strings, characters and comments are not imports; a lifetime is no literal.
    let literals = "fn f<'a>(x: &'a str) -> &'a str {\n    let q = '\"';\n    /* super::copy_tree */\n    \
                    let s = \"super::copy_tree \\\" crate::evaluate::run\";\n    \
                    let r = r#\"crate::evaluate::run \"# ;\n    x\n}\n";
    assert_eq!(upward("evaluate::embed", literals), Vec::<String>::new());
    assert_eq!(
        upward("evaluate::embed", &format!("{literals}super::copy_tree(a, b)?;\n")).len(),
        1
    );
    // Groups are expanded; one upward leaf is enough.
    let grouped = "use crate::{records::Record, report::write};\n";
    assert_eq!(upward("paper", grouped).len(), 1);
    // Experiments are independent: one may not use another.
    assert_eq!(
        upward("evaluate::drape", "use crate::evaluate::altconv::window;\n").len(),
        1
    );
    // The runner may use the experiments, and nothing may use the runner.
    assert!(upward("evaluate", "use crate::evaluate::drape::run;\n").is_empty());
    assert_eq!(upward("records", "crate::evaluate::run(&o)?;\n").len(), 1);
}
