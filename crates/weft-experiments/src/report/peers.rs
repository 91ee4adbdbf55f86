//! Points measured outside the evaluation, with a peer's own tools, for the report's
//! Pareto plots: `OUT/peers/*.json`, written by scripts such as
//! `benches/python/cloth_vs_newton.py` (NVIDIA Newton on the CPU against weft's cloth
//! ground truth). A peer runs in Python, so the evaluation cannot time it; the script
//! times weft's ground truth in the same run, and each point's time ratio is taken to
//! that run's weft time ([`PeerFile::baseline`]), never to the evaluation's.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Context, ensure};

/// One peer measurement: a scene, the reference every point is scored against, and the
/// points.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PeerFile {
    /// The experiment whose Pareto plot the points join (e.g. `sim`).
    pub experiment: String,
    pub scene: String,
    /// Frames every point simulated.
    pub frames: usize,
    pub frame_dt_s: f64,
    /// What every point's error is measured against.
    pub reference: String,
    /// The method (one of `points`) whose time per frame divides every point's: weft's
    /// ground truth, timed in the same run.
    pub baseline: String,
    /// Package versions of the peer and the script's tools.
    pub versions: BTreeMap<String, String>,
    /// The command that wrote the file.
    pub command: String,
    pub points: Vec<PeerPoint>,
}

/// One method and setting on the plane.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PeerPoint {
    pub method: String,
    /// Who computed it (`weft`, or the peer's name and version).
    pub solver: String,
    pub setting: String,
    /// Wall time per frame of the stepping alone (s).
    pub seconds_per_frame: f64,
    /// CPU threads the method used.
    pub threads: usize,
    /// Errors by the evaluation's metric names (`m-rms`, `max-error`, in mm); `None` when
    /// the run left the finite numbers.
    pub errors: BTreeMap<String, Option<f64>>,
    /// Newton iterations per frame (weft's points).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub newton_iterations_per_frame: Option<f64>,
}

impl PeerFile {
    /// Seconds per frame of [`PeerFile::baseline`].
    pub fn baseline_seconds(&self) -> crate::Result<f64> {
        let b = self
            .points
            .iter()
            .find(|p| p.method == self.baseline)
            .with_context(|| {
                format!(
                    "peer file for {}: baseline {:?} is not among its points",
                    self.scene, self.baseline
                )
            })?;
        Ok(b.seconds_per_frame)
    }

    /// Checks every number: positive finite times, a baseline among the points, finite
    /// non-negative errors (or none), distinct method names.
    pub fn validate(&self) -> crate::Result<()> {
        ensure!(!self.points.is_empty(), "peer file for {}: no points", self.scene);
        ensure!(self.frames > 0, "peer file for {}: frames is 0", self.scene);
        for p in &self.points {
            ensure!(
                p.seconds_per_frame.is_finite() && p.seconds_per_frame > 0.0,
                "peer file for {}: {} has seconds_per_frame {}",
                self.scene,
                p.method,
                p.seconds_per_frame
            );
            for (m, e) in &p.errors {
                if let Some(e) = e {
                    ensure!(
                        e.is_finite() && *e >= 0.0,
                        "peer file for {}: {} has {m} = {e}",
                        self.scene,
                        p.method
                    );
                }
            }
        }
        let names = crate::records::distinct(self.points.iter().map(|p| p.method.as_str()));
        ensure!(
            names.len() == self.points.len(),
            "peer file for {}: a method name repeats",
            self.scene
        );
        self.baseline_seconds()?;
        Ok(())
    }

    /// `(method, time ratio to the baseline, error)` for `metric`, the baseline itself and
    /// points without a finite error left out (the evaluation plots weft's own methods).
    pub fn pareto(&self, metric: &str) -> crate::Result<Vec<(String, f64, f64)>> {
        let base = self.baseline_seconds()?;
        Ok(self
            .points
            .iter()
            .filter(|p| p.solver != "weft")
            .filter_map(|p| {
                let e = (*p.errors.get(metric)?)?;
                Some((p.method.clone(), p.seconds_per_frame / base, e))
            })
            .collect())
    }
}

/// Every `dir/peers/*.json`, by file name; none when the directory does not exist.
pub fn read(dir: &Path) -> crate::Result<Vec<PeerFile>> {
    let peers = dir.join("peers");
    if !peers.exists() {
        return Ok(Vec::new());
    }
    let mut paths: Vec<_> = std::fs::read_dir(&peers)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    paths.sort();
    paths
        .iter()
        .map(|p| {
            let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            let f: PeerFile = serde_json::from_str(&text).with_context(|| format!("{} does not parse", p.display()))?;
            f.validate().with_context(|| format!("checking {}", p.display()))?;
            Ok(f)
        })
        .collect()
}

/// The markdown section listing every peer file's points.
pub fn markdown(files: &[PeerFile]) -> String {
    let mut s = String::new();
    if files.is_empty() {
        return s;
    }
    s.push_str("\n## Peers measured outside the evaluation\n\n");
    for f in files {
        let base = f.baseline_seconds().unwrap_or(f64::NAN);
        // Further error metrics the file gives (a second reference, a window), as columns.
        let extra: Vec<&str> = f
            .points
            .iter()
            .flat_map(|p| p.errors.keys())
            .map(String::as_str)
            .filter(|m| !matches!(*m, "m-rms" | "max-error"))
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        s.push_str(&format!(
            "`{}` / {}: {} frames of {} s, errors against {}; times from one run of `{}` ({}), ratio to `{}` in that \
             run.\n\n| method | solver | setting | threads | ms per frame | time ratio | M_rms (mm) | max error (mm) \
             |{}\n|---|---|---|---|---|---|---|---|{}\n",
            f.experiment,
            f.scene,
            f.frames,
            f.frame_dt_s,
            f.reference,
            f.command,
            f.versions
                .iter()
                .map(|(k, v)| format!("{k} {v}"))
                .collect::<Vec<_>>()
                .join(", "),
            f.baseline,
            extra.iter().map(|m| format!(" `{m}` (mm) |")).collect::<String>(),
            "---|".repeat(extra.len())
        ));
        let e = |p: &PeerPoint, m: &str| match p.errors.get(m) {
            Some(Some(v)) => format!("{v:.3}"),
            Some(None) => "diverged".into(),
            None => "—".into(),
        };
        for p in &f.points {
            s.push_str(&format!(
                "| {} | {} | {} | {} | {:.1} | {:.3} | {} | {} |{}\n",
                p.method,
                p.solver,
                p.setting,
                p.threads,
                1e3 * p.seconds_per_frame,
                p.seconds_per_frame / base,
                e(p, "m-rms"),
                e(p, "max-error"),
                extra.iter().map(|m| format!(" {} |", e(p, m))).collect::<String>()
            ));
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file() -> PeerFile {
        let point = |m: &str, solver: &str, s: f64, e: Option<f64>| PeerPoint {
            method: m.into(),
            solver: solver.into(),
            setting: String::new(),
            seconds_per_frame: s,
            threads: 1,
            errors: [("m-rms".to_string(), e)].into_iter().collect(),
            newton_iterations_per_frame: None,
        };
        PeerFile {
            experiment: "sim".into(),
            scene: "sheet-ms".into(),
            frames: 3,
            frame_dt_s: 0.02,
            reference: "r".into(),
            baseline: "weft-implicit-euler".into(),
            versions: BTreeMap::new(),
            command: "c".into(),
            points: vec![
                point("weft-implicit-euler", "weft", 2.0, Some(1.0)),
                point("peer-a", "peer", 0.5, Some(3.0)),
                point("peer-b", "peer", 0.25, None),
            ],
        }
    }

    #[test]
    fn ratios_divide_by_the_same_runs_baseline_and_skip_diverged_points() {
        let f = file();
        f.validate().unwrap();
        assert_eq!(f.pareto("m-rms").unwrap(), vec![("peer-a".to_string(), 0.25, 3.0)]);
        assert!(f.pareto("max-error").unwrap().is_empty());
        let md = markdown(&[f]);
        assert!(
            md.contains("| peer-b | peer |  | 1 | 250.0 | 0.125 | diverged | — |"),
            "{md}"
        );
        // A further metric one point gives becomes a column, a dash where a point lacks it.
        let mut f = file();
        f.points[1].errors.insert("m-rms-frames-1-2".into(), Some(0.5));
        let md = markdown(&[f]);
        assert!(md.contains("| max error (mm) | `m-rms-frames-1-2` (mm) |"), "{md}");
        assert!(md.contains("| 3.000 | — | 0.500 |"), "{md}");
        assert!(md.contains("| diverged | — | — |"), "{md}");
    }

    #[test]
    fn bad_files_are_refused_with_the_reason() {
        let mut f = file();
        f.baseline = "missing".into();
        assert!(f.validate().unwrap_err().to_string().contains("baseline"));
        let mut f = file();
        f.points[1].seconds_per_frame = f64::NAN;
        assert!(f.validate().unwrap_err().to_string().contains("peer-a"));
        let mut f = file();
        f.points[2].method = "peer-a".into();
        assert!(f.validate().unwrap_err().to_string().contains("repeats"));
    }

    #[test]
    fn read_takes_every_json_file_and_names_the_one_that_fails() {
        let dir = std::env::temp_dir().join(format!("weft-peers-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("peers")).unwrap();
        assert!(read(&dir.join("nowhere")).unwrap().is_empty());
        std::fs::write(dir.join("peers/a.json"), serde_json::to_string(&file()).unwrap()).unwrap();
        assert_eq!(read(&dir).unwrap(), vec![file()]);
        std::fs::write(dir.join("peers/b.json"), "{}").unwrap();
        let e = read(&dir).unwrap_err();
        assert!(format!("{e}").contains("b.json"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
