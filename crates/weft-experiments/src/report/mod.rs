//! The evaluation report: `results.json`, `tables.md`, plots (PNG and SVG), rendered
//! error images and one self-contained `index.html`, all rebuilt from the experiments'
//! outputs. Also the check CI runs on a report (`cargo xtask check-report`).

pub mod compare;
pub mod html;
pub mod peers;
pub mod plots;
pub mod published;
pub mod summary;

use std::path::Path;

use crate::error::{Context, ensure};

use crate::paper;
use crate::records::distinct;
use crate::records::{ExperimentOutput, Record};
use plots::ParetoPoint;
use weft_data::Size;
use weft_data::files::{write_json, write_text};

/// The error metric each experiment's Pareto plot uses, and the split it is read on
/// (`None`: every record of the metric).
fn pareto_metric(experiment: &str) -> (&'static str, &'static str, Option<&'static str>) {
    match experiment {
        "proj" => ("sqrt-mse", "SqrtMSE against the tight reference (mm)", None),
        "nnwarp" => ("rel-error", "rel-error against full nonlinear FEM", None),
        "drape" => ("sqrtmse-mm", "SqrtMSE on the test split (mm)", Some("test")),
        "altconv" => (
            "error-mm-rollout50",
            "50-step roll-out error on unseen motions (mm)",
            Some("test"),
        ),
        _ => ("m-rms", "M_rms against the tight reference (mm)", None),
    }
}

/// The charts of one experiment, as (title, file stem relative to the report).
#[derive(Debug, Default)]
pub struct Charts {
    pub pareto: Vec<(String, String)>,
    pub rollout: Vec<(String, String)>,
    pub energy: Vec<(String, String)>,
    pub scatter: Vec<(String, String)>,
    pub lines: Vec<(String, String)>,
}

pub fn write(out: &Path, size: Size, outputs: &[ExperimentOutput]) -> crate::Result<()> {
    let records: Vec<Record> = outputs.iter().flat_map(|o| o.records.iter().cloned()).collect();
    crate::records::validate(&records)?;
    write_json(&out.join("results.json"), &records)?;
    let peer_files = peers::read(out)?;
    let plot_dir = out.join("plots");
    std::fs::create_dir_all(&plot_dir)?;
    let mut charts = Vec::new();
    for o in outputs {
        let mut c = Charts {
            pareto: Vec::new(),
            rollout: Vec::new(),
            energy: Vec::new(),
            scatter: Vec::new(),
            lines: Vec::new(),
        };
        let (metric, label, split) = pareto_metric(&o.experiment);
        let plotted = |r: &&Record| r.metric == metric && (split.is_none() || r.split.as_deref() == split);
        for scene in distinct(o.records.iter().filter(plotted).map(|r| r.scene.as_str())) {
            let points: Vec<ParetoPoint> = o
                .records
                .iter()
                .filter(plotted)
                .filter(|r| r.scene == scene)
                .filter_map(|r| {
                    Some(ParetoPoint {
                        method: r.method.clone(),
                        time_ratio: r.seconds_per_frame? / r.ground_truth_seconds_per_frame?,
                        error: r.value,
                        peer: false,
                    })
                })
                .collect();
            let mut points = points;
            for f in peer_files
                .iter()
                .filter(|f| f.experiment == o.experiment && f.scene == scene)
            {
                for (method, time_ratio, error) in f.pareto(metric)? {
                    points.push(ParetoPoint {
                        method,
                        time_ratio,
                        error,
                        peer: true,
                    });
                }
            }
            let stem = format!("plots/pareto-{}-{}", o.experiment, slug(scene));
            let title = format!("{} / {scene}: speed against accuracy", o.experiment);
            plots::pareto(&out.join(&stem), &title, label, &points)?;
            c.pareto.push((title, stem));
        }
        for scene in distinct(o.curves.iter().map(|c| c.scene.as_str())) {
            let curves: Vec<_> = o.curves.iter().filter(|c| c.scene == scene).collect();
            let stem = format!("plots/rollout-{}-{}", o.experiment, slug(scene));
            let title = format!("{} / {scene}: roll-out error against frame", o.experiment);
            plots::rollout(&out.join(&stem), &title, &curves)?;
            c.rollout.push((title, stem));
        }
        for scene in distinct(o.energies.iter().map(|e| e.scene.as_str())) {
            let bars: Vec<_> = o.energies.iter().filter(|e| e.scene == scene).collect();
            let stem = format!("plots/energy-{}-{}", o.experiment, slug(scene));
            let title = format!("{} / {scene}: mean energies", o.experiment);
            plots::energy(&out.join(&stem), &title, &bars)?;
            c.energy.push((title, stem));
        }
        for sc in &o.scatters {
            let stem = format!(
                "plots/scatter-{}-{}-{}",
                o.experiment,
                slug(&sc.scene),
                slug(&sc.method)
            );
            plots::scatter(&out.join(&stem), sc)?;
            c.scatter.push((sc.title.clone(), stem));
        }
        for l in &o.lines {
            let stem = format!("plots/{}-{}", o.experiment, slug(&l.name));
            plots::lines(&out.join(&stem), l)?;
            c.lines.push((l.title.clone(), stem));
        }
        charts.push(c);
    }
    // The summary: the papers' claims and one plot per family of scenes.
    let claims = summary::claims(outputs);
    let families = family_figures(out, &records)?;
    let tables = paper::tables(outputs);
    write_text(
        &out.join("tables.md"),
        &(tables_markdown(size, outputs, &claims, &tables) + &peers::markdown(&peer_files)),
    )?;
    let page = html::page(
        out,
        size,
        outputs,
        &html::Summary {
            claims: &claims,
            families: &families,
        },
        &tables,
        &charts,
    )?;
    write_text(&out.join("index.html"), &page)?;
    Ok(())
}

/// One small-multiples figure per family of scenes (`summary::FAMILIES`): a panel per scene
/// and error kind, a row per kind (and per shape of NNWarp's `shape/material` scenes), the
/// header saying what each kind of error measures. Returns (title, file stem) per figure.
fn family_figures(out: &Path, records: &[Record]) -> crate::Result<Vec<(String, String)>> {
    let mut families = Vec::new();
    for f in summary::FAMILIES {
        let panels = f.panels(records);
        if panels.is_empty() {
            continue;
        }
        let mut groups: Vec<Vec<plots::Panel>> = Vec::new();
        let mut last = None;
        for p in &panels {
            let key = (p.kind, p.scene.split_once('/').map(|(shape, _)| shape.to_string()));
            if last.as_ref() != Some(&key) {
                groups.push(Vec::new());
                last = Some(key);
            }
            groups.last_mut().expect("a group was just pushed").push(plots::Panel {
                title: p.title(),
                error_label: p.error_label.clone(),
                legend: p.kind.as_str().to_string(),
                points: p
                    .points
                    .iter()
                    .map(|q| ParetoPoint {
                        method: q.method.clone(),
                        time_ratio: q.time_ratio,
                        error: q.error,
                        peer: false,
                    })
                    .collect(),
            });
        }
        let mut notes = vec![
            "One panel per scene and kind of error, never averaged across scenes; a point is one method's error on \
             that scene against its time per frame over the ground truth's, both from one run. Lower left is \
             better; the grey line is the panel's Pareto front."
                .to_string(),
        ];
        for kind in distinct(panels.iter().map(|p| p.kind.as_str())) {
            let meaning = panels
                .iter()
                .find(|p| p.kind.as_str() == kind)
                .map(|p| p.kind.meaning());
            notes.push(format!("{kind}: {}.", meaning.unwrap_or_default()));
        }
        if panels.iter().flat_map(|p| &p.points).any(|q| q.error <= 0.0) {
            notes.push("An error of 0 (a method identical to the reference) sits on its panel's floor.".into());
        }
        let stem = format!("plots/family-{}", f.name);
        plots::small_multiples(&out.join(&stem), f.title, &notes, &groups)?;
        families.push((f.title.to_string(), stem));
    }
    Ok(families)
}

/// Distinct names in first-seen order.
fn slug(s: &str) -> String {
    s.replace('/', "-")
}

fn tables_markdown(
    size: Size,
    outputs: &[ExperimentOutput],
    claims: &[summary::Claim],
    tables: &[paper::Table],
) -> String {
    let mut s = format!(
        "# weft evaluation ({} size)\n\nEvery figure below was measured by `cargo xtask evaluate --size {}`, each \
         experiment in one run of its own ({}). Time ratios compare methods timed in the same run.\n\n",
        size.as_str(),
        size.as_str(),
        experiment_times(outputs, |e| format!("`{e}`"))
    );
    s.push_str(
        "## The papers' claims\n\n| paper | claim | paper | ours | verdict | decided by |\n|---|---|---|---|---|---|\n",
    );
    for c in claims {
        s.push_str(&format!(
            "| {} | {} | {} | {} | **{}** | `{}` |\n",
            c.paper,
            c.claim,
            c.paper_figure,
            c.ours,
            c.verdict.as_str(),
            c.command()
        ));
    }
    s.push('\n');
    let stale = published::stale(outputs);
    if !stale.is_empty() {
        s.push_str(&format!("{STALE_CAPTION}\n\n"));
        for e in &stale {
            s.push_str(&format!("- {e}\n"));
        }
        s.push('\n');
    }
    for t in tables {
        s.push_str(&t.markdown());
    }
    let ran: Vec<&str> = outputs.iter().map(|o| o.experiment.as_str()).collect();
    let pending = paper::pending(&ran);
    if !pending.is_empty() {
        s.push_str("## Tables that later experiments fill\n\n");
        for (what, exp) in pending {
            s.push_str(&format!("- {what}: experiment `{exp}`, not yet in this evaluation.\n"));
        }
        s.push('\n');
    }
    s.push_str("## Notes\n\n");
    for o in outputs {
        for n in &o.notes {
            s.push_str(&format!("- {n}\n"));
        }
        for f in &o.failures {
            s.push_str(&format!("- **failed**: {f}\n"));
        }
    }
    s
}

/// Each experiment's wall time and their total ("experiments' wall time: `sim` 955 s, `proj`
/// 14 s; 969 s (16 min) in all"): the seconds each experiment took when it ran, kept in its
/// cached output. The seconds spent assembling the report are not worth printing: rebuilt
/// from cached outputs it takes a second ("report assembled in 0 s" said nothing).
pub(crate) fn experiment_times(outputs: &[ExperimentOutput], name: impl Fn(&str) -> String) -> String {
    let total: f64 = outputs.iter().map(|o| o.wall_seconds).sum();
    let each = outputs
        .iter()
        .map(|o| format!("{} {:.0} s", name(&o.experiment), o.wall_seconds))
        .collect::<Vec<_>>()
        .join(", ");
    let human = if total >= 3600.0 {
        format!("{:.1} h", total / 3600.0)
    } else {
        format!("{:.0} min", total / 60.0)
    };
    format!("experiments' wall time: {each}; {total:.0} s ({human}) in all")
}

/// What the page and `tables.md` say beneath the claims when some experiment was made
/// before the publication rules ([`published::stale`]).
const STALE_CAPTION: &str = "Due for republication: these experiments were made before a publication had to come \
     from committed code and learned experiments wrote a record per seed; their figures stand as published, but a \
     reader cannot recompute their spreads or trace them to a commit:";

/// What [`check`] found in a report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CheckSummary {
    pub records: usize,
    /// Plot, render and prediction files read back.
    pub files: usize,
    /// A published report's experiments due for republication, each with the reason
    /// ([`published::check`]); empty for a run's report.
    pub stale: Vec<String>,
}

/// `cargo xtask check-report DIR`: every output exists and parses, every record has every
/// field with a valid value, every prediction file reads back with matching shapes. A
/// `published` report (`evaluate --publish`, e.g. `docs/results`) must have its
/// `PROVENANCE.md`, and its predictions, which are not committed, are not required.
pub fn check(dir: &Path, published: bool) -> crate::Result<CheckSummary> {
    let results = dir.join("results.json");
    let text = std::fs::read_to_string(&results).with_context(|| format!("reading {}", results.display()))?;
    let raw: Vec<serde_json::Value> = serde_json::from_str(&text).with_context(|| {
        format!(
            "{} does not parse as a JSON array of records (JSON has no NaN or Infinity)",
            results.display()
        )
    })?;
    ensure!(!raw.is_empty(), "results.json holds no record");
    const FIELDS: [&str; 11] = [
        "experiment",
        "scene",
        "method",
        "metric",
        "split",
        "value",
        "unit",
        "paper_value",
        "seconds_per_frame",
        "ground_truth_seconds_per_frame",
        "seed",
    ];
    for (i, r) in raw.iter().enumerate() {
        let obj = r.as_object().with_context(|| format!("record {i} is not an object"))?;
        for f in FIELDS {
            ensure!(obj.contains_key(f), "record {i} lacks field {f:?}: {r}");
        }
        ensure!(
            obj.len() == FIELDS.len(),
            "record {i} has fields beyond the documented eleven: {r}"
        );
    }
    let records: Vec<Record> = serde_json::from_str(&text).context("results.json records do not parse")?;
    crate::records::validate(&records)?;
    // One value per (experiment, scene, method, metric, split, seed): a second would make
    // every table and claim depend on which one a reader happens to take.
    let mut keys = std::collections::HashSet::new();
    for r in &records {
        ensure!(
            keys.insert((&r.experiment, &r.scene, &r.method, &r.metric, &r.split, r.seed)),
            "results.json holds two records of experiment {:?}, scene {:?}, method {:?}, metric {:?}, split {:?}, \
             seed {:?}",
            r.experiment,
            r.scene,
            r.method,
            r.metric,
            r.split,
            r.seed
        );
    }
    published::check_seed_records(&records)?;
    peers::read(dir)?;
    for f in ["tables.md", "index.html"] {
        let path = dir.join(f);
        let t = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
        ensure!(t.len() > 100, "{f} is nearly empty");
    }
    let html = std::fs::read_to_string(dir.join("index.html"))?;
    ensure!(
        !html.contains("src=\"plots/") && !html.contains("src=\"renders/"),
        "index.html links files instead of embedding them"
    );
    // The page a newcomer reads first: the claims, then every experiment the records hold.
    ensure!(
        html.contains("id=\"claims\"") && html.contains("id=\"contents\""),
        "index.html does not open with the claims table and contents (rebuild it from the experiments' outputs)"
    );
    for e in distinct(records.iter().map(|r| r.experiment.as_str())) {
        ensure!(
            html.contains(&format!("id=\"experiment-{e}\"")),
            "results.json holds experiment {e:?} but index.html has no section for it (rebuild the report from every \
             experiment's output)"
        );
    }
    let stale = if published {
        let path = dir.join("PROVENANCE.md");
        let t = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
        ensure!(t.contains("cargo xtask"), "PROVENANCE.md names no command");
        published::check(dir, &records)?
    } else {
        Vec::new()
    };
    let mut files = 0;
    for sub in ["plots", "renders", "predictions"] {
        if published && sub == "predictions" && !dir.join(sub).exists() {
            continue;
        }
        for path in walk(&dir.join(sub))? {
            let bytes = std::fs::read(&path)?;
            match path.extension().and_then(|e| e.to_str()) {
                Some("png") => ensure!(bytes.starts_with(b"\x89PNG"), "{} is not a PNG", path.display()),
                Some("svg") => ensure!(
                    String::from_utf8_lossy(&bytes).contains("<svg"),
                    "{} is not an SVG",
                    path.display()
                ),
                Some("safetensors") => {
                    let st = safetensors::SafeTensors::deserialize(&bytes)
                        .with_context(|| format!("{} does not parse", path.display()))?;
                    let p = st
                        .tensor("positions")
                        .with_context(|| format!("{}: no positions", path.display()))?;
                    let g = st
                        .tensor("ground_truth")
                        .with_context(|| format!("{}: no ground_truth", path.display()))?;
                    ensure!(
                        p.shape() == g.shape(),
                        "{}: positions and ground truth differ in shape",
                        path.display()
                    );
                }
                _ => continue,
            }
            files += 1;
        }
    }
    // Every experiment/scene/method with an error metric has its predictions (a published
    // report leaves them out).
    let predictions = !published || dir.join("predictions").exists();
    for r in records.iter().filter(|_| predictions).filter(|r| {
        r.metric == "m-rms"
            || r.metric == "sqrt-mse"
            || (r.metric == "error-mm-rollout10" && r.is_test())
            || (r.metric == "sqrtmse-mm" && r.is_test())
    }) {
        let p = dir
            .join("predictions")
            .join(&r.experiment)
            .join(&r.scene)
            .join(format!("{}.safetensors", r.method));
        ensure!(p.exists(), "{} is missing", p.display());
    }
    Ok(CheckSummary {
        records: records.len(),
        files,
        stale,
    })
}

fn walk(dir: &Path) -> crate::Result<Vec<std::path::PathBuf>> {
    let mut out = Vec::new();
    if !dir.exists() {
        crate::error::bail!("{} is missing", dir.display());
    }
    for e in std::fs::read_dir(dir)? {
        let p = e?.path();
        if p.is_dir() {
            out.extend(walk(&p)?);
        } else {
            out.push(p);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {

    use super::*;

    #[test]
    fn a_report_with_two_records_of_one_cell_fails_the_check_naming_the_cell() {
        let dir = std::env::temp_dir().join(format!("weft-check-duplicates-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let record = |value: f64| {
            serde_json::json!({
                "experiment": "proj", "scene": "sheet", "method": "socp", "metric": "m-rms",
                "split": "test", "value": value, "unit": "mm", "paper_value": null,
                "seconds_per_frame": null, "ground_truth_seconds_per_frame": null, "seed": null
            })
        };
        std::fs::write(
            dir.join("results.json"),
            serde_json::to_string(&vec![record(1.0), record(2.0)]).unwrap(),
        )
        .unwrap();
        let e = check(&dir, false).unwrap_err().to_string();
        assert!(e.contains("two records") && e.contains("\"socp\""), "{e}");
        // One record of the cell passes this check and fails later, on the missing tables.
        std::fs::write(
            dir.join("results.json"),
            serde_json::to_string(&vec![record(1.0)]).unwrap(),
        )
        .unwrap();
        let e = anyhow_chain(check(&dir, false).unwrap_err());
        assert!(!e.contains("two records"), "{e}");
        // A missing report names its path.
        let missing = dir.join("absent");
        let e = anyhow_chain(check(&missing, false).unwrap_err());
        assert!(e.contains(&missing.join("results.json").display().to_string()), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The error and its sources, as `anyhow`'s `{:#}` prints them.
    fn anyhow_chain(e: crate::Error) -> String {
        let mut out = e.to_string();
        let mut source = std::error::Error::source(&e);
        while let Some(s) = source {
            out.push_str(": ");
            out.push_str(&s.to_string());
            source = s.source();
        }
        out
    }
}
