//! Two reports' figures compared cell by cell, timings aside: how a change that must not
//! move a figure (a restructuring, a dependency update) is shown not to, by running the
//! quick evaluation before and after (`cargo xtask check-report NEW --against OLD`).
//!
//! A cell is (experiment, scene, method, metric, split), unique within a report (the check
//! refuses duplicates). Wall times (records in `s` or `1/s`, and every record's seconds
//! fields) differ from run to run and are not compared.

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::Context;
use crate::records::Record;

/// What two reports' records hold in common and how far their figures lie apart.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// Cells of the first report missing from the second, and the reverse.
    pub only_in_first: Vec<String>,
    pub only_in_second: Vec<String>,
    /// Cells compared (both reports, not a timing).
    pub compared: usize,
    /// Cells whose values differ at all.
    pub differing: usize,
    /// The largest relative difference `|a − b| / max(|a|, |b|)` and its cell.
    pub largest: Option<(f64, String)>,
}

impl Comparison {
    /// Whether the reports hold the same cells and every figure agrees within `rtol`.
    pub fn agrees(&self, rtol: f64) -> bool {
        self.only_in_first.is_empty()
            && self.only_in_second.is_empty()
            && self.largest.as_ref().is_none_or(|(d, _)| *d <= rtol)
    }
}

fn cells(dir: &Path) -> crate::Result<BTreeMap<String, f64>> {
    let path = dir.join("results.json");
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let records: Vec<Record> =
        serde_json::from_str(&text).with_context(|| format!("{} does not parse as records", path.display()))?;
    Ok(records
        .into_iter()
        .filter(|r| r.unit != "s" && r.unit != "1/s")
        .map(|r| {
            let split = r.split.as_deref().unwrap_or("-");
            (
                format!("{}/{}/{}/{}/{split}", r.experiment, r.scene, r.method, r.metric),
                r.value,
            )
        })
        .collect())
}

/// Compares the `results.json` of the reports in `first` and `second`.
pub fn compare(first: &Path, second: &Path) -> crate::Result<Comparison> {
    let (a, b) = (cells(first)?, cells(second)?);
    let mut c = Comparison {
        only_in_first: a.keys().filter(|k| !b.contains_key(*k)).cloned().collect(),
        only_in_second: b.keys().filter(|k| !a.contains_key(*k)).cloned().collect(),
        compared: 0,
        differing: 0,
        largest: None,
    };
    for (key, x) in &a {
        let Some(y) = b.get(key) else { continue };
        c.compared += 1;
        if x == y {
            continue;
        }
        c.differing += 1;
        let d = (x - y).abs() / x.abs().max(y.abs());
        if c.largest.as_ref().is_none_or(|(m, _)| d > *m) {
            c.largest = Some((d, key.clone()));
        }
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(dir: &Path, rows: &[(&str, f64, &str)]) {
        std::fs::create_dir_all(dir).unwrap();
        let records: Vec<serde_json::Value> = rows
            .iter()
            .map(|(method, value, unit)| {
                serde_json::json!({
                    "experiment": "sim", "scene": "sheet-ms", "method": method, "metric": "m-rms",
                    "split": null, "value": value, "unit": unit, "paper_value": null,
                    "seconds_per_frame": null, "ground_truth_seconds_per_frame": null
                })
            })
            .collect();
        std::fs::write(dir.join("results.json"), serde_json::to_string(&records).unwrap()).unwrap();
    }

    #[test]
    fn figures_are_compared_by_cell_with_timings_aside() {
        let root = std::env::temp_dir().join(format!("weft-compare-{}", std::process::id()));
        let (a, b) = (root.join("a"), root.join("b"));
        report(
            &a,
            &[("x", 2.0, "mm"), ("y", 1.0, "mm"), ("t", 1.0, "s"), ("gone", 1.0, "mm")],
        );
        report(
            &b,
            &[("x", 2.0, "mm"), ("y", 1.5, "mm"), ("t", 9.0, "s"), ("new", 1.0, "mm")],
        );
        let c = compare(&a, &b).unwrap();
        assert_eq!(c.compared, 2, "the timing is not compared");
        assert_eq!(c.differing, 1);
        // |1 − 1.5| / 1.5
        let (d, cell) = c.largest.clone().unwrap();
        assert!(
            (d - 1.0 / 3.0).abs() < 1e-15 && cell == "sim/sheet-ms/y/m-rms/-",
            "{d} {cell}"
        );
        assert_eq!(c.only_in_first, vec!["sim/sheet-ms/gone/m-rms/-".to_string()]);
        assert_eq!(c.only_in_second, vec!["sim/sheet-ms/new/m-rms/-".to_string()]);
        assert!(!c.agrees(1.0));
        // The same report agrees with itself exactly.
        let same = compare(&a, &a).unwrap();
        assert!(same.agrees(0.0) && same.differing == 0 && same.largest.is_none());
        let _ = std::fs::remove_dir_all(&root);
    }
}
