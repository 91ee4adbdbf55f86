//! The docs quote the published report (`docs/results/`) only through marked figures, and a
//! marked figure must be the report's value at the precision it is written with: one figure
//! per fact across the docs and the report (issue 72).
//!
//! A mark is an HTML comment right after the number it vouches for (Markdown hides it):
//!
//! ```text
//! reconstructs to 6.65 mm<!-- report: record embed sheet-ms ours m-rms test -->
//! frame 11: 14.9 mm<!-- report: curve embed sheet-ms ours 11 error_mm -->
//! ```
//!
//! `record EXPERIMENT SCENE METHOD METRIC [SPLIT] [seed=N]` names one record of
//! `docs/results/results.json` (without `seed=`, the one without a seed: the seeds' mean); `curve EXPERIMENT SCENE METHOD FRAME FIELD` one point of a
//! curve in `docs/results/experiments/EXPERIMENT.json`. The number may carry a unit; a time
//! written in `ms` or `µs` is compared with a record in `s`. Written with d decimals (and an
//! exponent e), it must be within half a unit of its last digit, `0.5 × 10^(e − d)`, of the
//! published value. After a republication (`cargo xtask evaluate … --publish docs/results`)
//! rerun `cargo test --release -p weft-integration quoted_figures`: each drifted figure is
//! reported with its file, line and the value to write instead, at the same precision.

use std::path::{Path, PathBuf};

use serde_json::Value;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

const OPEN: &str = "<!-- report:";
const CLOSE: &str = "-->";

/// One marked figure: where, the number as written, its unit, and the mark's words.
#[derive(Debug, PartialEq)]
struct Quote {
    line: usize,
    written: String,
    unit: String,
    mark: Vec<String>,
}

/// Every marked figure of one document, in order; an error for a mark with no number
/// before it or no end.
fn quotes(text: &str) -> Result<Vec<Quote>, String> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let mut rest = line;
        while let Some(at) = rest.find(OPEN) {
            let before = &rest[..at];
            let after = &rest[at + OPEN.len()..];
            let end = after
                .find(CLOSE)
                .ok_or_else(|| format!("line {}: a report mark without `-->`", i + 1))?;
            let mark: Vec<String> = after[..end].split_whitespace().map(String::from).collect();
            let (written, unit) =
                trailing_number(before).ok_or_else(|| format!("line {}: no number before the mark {mark:?}", i + 1))?;
            out.push(Quote {
                line: i + 1,
                written,
                unit,
                mark,
            });
            rest = &after[end + CLOSE.len()..];
        }
    }
    Ok(out)
}

/// The number a text ends with, and the unit written after it (`14.9 mm` → `("14.9",
/// "mm")`); emphasis and a closing bracket around it are skipped.
fn trailing_number(text: &str) -> Option<(String, String)> {
    let text = text.trim_end().trim_end_matches(['*', ')', '`']);
    let unit_start = text
        .char_indices()
        .rev()
        .find(|(_, c)| c.is_ascii_digit() || c.is_whitespace())
        .map_or(0, |(i, c)| i + c.len_utf8());
    let unit = text[unit_start..].to_string();
    let body = text[..unit_start].trim_end();
    let start = body
        .char_indices()
        .rev()
        .take_while(|(_, c)| c.is_ascii_digit() || matches!(c, '.' | ',' | 'e' | '-' | '+'))
        .last()
        .map(|(i, _)| i)?;
    let written = body[start..].trim_start_matches(['-', '+', 'e']).to_string();
    written
        .starts_with(|c: char| c.is_ascii_digit())
        .then_some((written, unit))
}

/// The written number's value and half a unit of its last digit.
fn value_and_resolution(written: &str) -> Option<(f64, f64)> {
    let plain = written.replace(',', "");
    let (mantissa, exponent) = match plain.split_once('e') {
        Some((m, e)) => (m, e.parse::<i32>().ok()?),
        None => (plain.as_str(), 0),
    };
    let decimals = mantissa.split_once('.').map_or(0, |(_, d)| d.len()) as i32;
    Some((plain.parse().ok()?, 0.5 * 10f64.powi(exponent - decimals)))
}

/// `value` written with as many digits as `written`.
fn same_precision(value: f64, written: &str) -> String {
    let plain = written.replace(',', "");
    let (mantissa, exponent) = plain
        .split_once('e')
        .map_or((plain.as_str(), false), |(m, _)| (m, true));
    let decimals = mantissa.split_once('.').map_or(0, |(_, d)| d.len());
    if exponent {
        format!("{value:.decimals$e}")
    } else {
        format!("{value:.decimals$}")
    }
}

/// The published value a mark names, in the record's unit, with a label for messages.
fn published(mark: &[String], records: &[Value], results: &Path) -> Result<(f64, String, String), String> {
    let words: Vec<&str> = mark.iter().map(String::as_str).collect();
    match words.as_slice() {
        ["record", experiment, scene, method, metric, rest @ ..] => {
            // A per-seed record is named by `seed=N`; without it the mark means the seeds'
            // mean (the record without a seed).
            let seed = rest
                .iter()
                .find_map(|w| w.strip_prefix("seed="))
                .map(|n| n.parse::<u64>());
            let seed = seed
                .transpose()
                .map_err(|_| format!("unreadable mark {mark:?}: seed=N"))?;
            let split = rest.iter().find(|w| !w.starts_with("seed=")).copied();
            let found: Vec<&Value> = records
                .iter()
                .filter(|r| {
                    r["experiment"] == *experiment
                        && r["scene"] == *scene
                        && r["method"] == *method
                        && r["metric"] == *metric
                        && split.is_none_or(|s| r["split"] == s)
                        && r.get("seed").and_then(Value::as_u64) == seed
                })
                .collect();
            let label = format!(
                "record {experiment}/{scene}/{method}/{metric}{}",
                split.map_or(String::new(), |s| format!(" ({s})"))
            );
            match found.as_slice() {
                [r] => Ok((
                    r["value"].as_f64().ok_or(format!("{label}: no value"))?,
                    r["unit"].as_str().unwrap_or("").to_string(),
                    label,
                )),
                [] => Err(format!("{label} is not in results.json")),
                _ => Err(format!("{label} matches {} records; name the split", found.len())),
            }
        }
        ["curve", experiment, scene, method, frame, field] => {
            let path = results.join("experiments").join(format!("{experiment}.json"));
            let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            let output: Value = serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
            let label = format!("curve {experiment}/{scene}/{method} frame {frame} {field}");
            let frame: f64 = frame
                .parse()
                .map_err(|_| format!("{label}: the frame is not a number"))?;
            let curve = output["curves"]
                .as_array()
                .and_then(|cs| cs.iter().find(|c| c["scene"] == *scene && c["method"] == *method))
                .ok_or(format!("{label}: no such curve"))?;
            let index = curve["frames"]
                .as_array()
                .and_then(|fs| fs.iter().position(|f| f.as_f64() == Some(frame)))
                .ok_or(format!("{label}: no such frame"))?;
            let value = curve[*field][index].as_f64().ok_or(format!("{label}: no such field"))?;
            Ok((value, if field.ends_with("_mm") { "mm" } else { "" }.to_string(), label))
        }
        _ => Err(format!(
            "unreadable mark {mark:?}: `record EXPERIMENT SCENE METHOD METRIC [SPLIT] [seed=N]` or `curve EXPERIMENT SCENE METHOD FRAME FIELD`"
        )),
    }
}

/// Every mismatch between one document's marked figures and the published report.
fn check(doc: &Path, records: &[Value], results: &Path) -> (usize, Vec<String>) {
    let text = std::fs::read_to_string(doc).unwrap_or_else(|e| panic!("{}: {e}", doc.display()));
    let name = doc.strip_prefix(root()).unwrap_or(doc).display().to_string();
    let quotes = match quotes(&text) {
        Ok(q) => q,
        Err(e) => return (0, vec![format!("{name}: {e}")]),
    };
    let mut problems = Vec::new();
    for q in &quotes {
        let at = format!("{name}:{}", q.line);
        let (value, unit, label) = match published(&q.mark, records, results) {
            Ok(p) => p,
            Err(e) => {
                problems.push(format!("{at}: {e}"));
                continue;
            }
        };
        let scale = match (unit.as_str(), q.unit.as_str()) {
            ("s", "ms") => 1e3,
            ("s", "µs") => 1e6,
            _ => 1.0,
        };
        let Some((written, half)) = value_and_resolution(&q.written) else {
            problems.push(format!("{at}: `{}` is not a number", q.written));
            continue;
        };
        let expected = value * scale;
        if (written - expected).abs() > half * (1.0 + 1e-9) {
            problems.push(format!(
                "{at}: writes {} {} for {label}; the report has {} {}",
                q.written,
                q.unit,
                same_precision(expected, &q.written),
                q.unit
            ));
        }
    }
    (quotes.len(), problems)
}

#[test]
fn every_marked_figure_in_the_docs_is_the_published_one() {
    let results = root().join("docs/results");
    let text = std::fs::read_to_string(results.join("results.json")).expect("docs/results/results.json");
    let records: Vec<Value> = serde_json::from_str(&text).expect("results.json is a list of records");
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs/")
        .map(|e| e.expect("docs/ entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.push(root().join("README.md"));
    docs.sort();
    let (mut marked, mut problems) = (0, Vec::new());
    let mut in_benchmarks = 0;
    for doc in &docs {
        let (n, p) = check(doc, &records, &results);
        if doc.ends_with("BENCHMARKS.md") {
            in_benchmarks = n;
        }
        marked += n;
        problems.extend(p);
    }
    assert!(
        problems.is_empty(),
        "{} of {marked} marked figures differ from docs/results:\n{}",
        problems.len(),
        problems.join("\n")
    );
    // BENCHMARKS.md quotes the report's accuracy beside its speed figures; losing every mark
    // there would leave those quotes unchecked.
    assert!(in_benchmarks > 0, "docs/BENCHMARKS.md has no report marks");
}

#[test]
fn marks_read_the_number_before_them_at_its_precision() {
    let text = "to **6.65 mm**<!-- report: record embed sheet-ms ours m-rms test --> and 1,462 ms<!-- report: curve sim sheet-ms implicit-euler 3 error_mm -->\n\
                none <!-- report: record a b c d -->";
    let err = quotes(text).unwrap_err();
    assert!(err.starts_with("line 2: no number"), "{err}");
    let q = quotes(text.lines().next().unwrap()).unwrap();
    assert_eq!(q.len(), 2);
    assert_eq!((q[0].written.as_str(), q[0].unit.as_str()), ("6.65", "mm"));
    assert_eq!(q[0].mark, ["record", "embed", "sheet-ms", "ours", "m-rms", "test"]);
    assert_eq!((q[1].written.as_str(), q[1].unit.as_str()), ("1,462", "ms"));
    assert_eq!(value_and_resolution("6.65"), Some((6.65, 0.5 * 10f64.powi(-2))));
    assert_eq!(value_and_resolution("1,462"), Some((1462.0, 0.5)));
    assert_eq!(
        value_and_resolution("3.9402e-2"),
        Some((3.9402e-2, 0.5 * 10f64.powi(-6)))
    );
    // A record that is not published, and one figure off by more than its last digit.
    let records: Vec<Value> = serde_json::from_str(
        r#"[{"experiment":"embed","scene":"sheet-ms","method":"ours","metric":"m-rms","split":"test","value":6.647,"unit":"mm"},
            {"experiment":"embed","scene":"sheet-ms","method":"ours","metric":"m-rms","split":"test","seed":1,"value":7.1,"unit":"mm"},
            {"experiment":"sim","scene":"beam","method":"nnwarp","metric":"frame-seconds","split":null,"value":0.0107,"unit":"s"}]"#,
    )
    .unwrap();
    let here = root().join("docs/results");
    let mark = |s: &str| s.split_whitespace().map(String::from).collect::<Vec<_>>();
    assert_eq!(
        published(&mark("record embed sheet-ms ours m-rms test"), &records, &here)
            .unwrap()
            .0,
        6.647
    );
    assert_eq!(
        published(&mark("record embed sheet-ms ours m-rms test seed=1"), &records, &here)
            .unwrap()
            .0,
        7.1
    );
    assert!(published(&mark("record embed sheet-ms ours m-sted"), &records, &here).is_err());
    let dir = std::env::temp_dir().join(format!("weft-quoted-figures-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let doc = dir.join("DOC.md");
    std::fs::write(
        &doc,
        "6.65 mm<!-- report: record embed sheet-ms ours m-rms test -->, 6.6 mm<!-- report: record embed sheet-ms ours m-rms test -->\n\
         6.7 mm<!-- report: record embed sheet-ms ours m-rms -->, 10.7 ms<!-- report: record sim beam nnwarp frame-seconds -->\n\
         11 ms<!-- report: record sim beam nnwarp frame-seconds -->",
    )
    .unwrap();
    let (n, problems) = check(&doc, &records, &here);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(n, 5);
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(
        problems[0].contains(":2: writes 6.7 mm") && problems[0].ends_with("the report has 6.6 mm"),
        "{problems:?}"
    );
    assert_eq!(same_precision(0.039402, "3.9e-2"), "3.9e-2");
}
