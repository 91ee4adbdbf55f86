//! `cargo xtask evaluate`: every method against its reference, speed beside accuracy.
//!
//! Each experiment (`sim`, `proj`, `embed`, `nnwarp`, `altconv`, `drape`) runs its methods and a tight
//! reference in one process, so time ratios compare one machine state, and returns an
//! [`ExperimentOutput`]: tidy [`Record`](crate::records::Record)s, roll-out curves, energies and renders. Outputs
//! are cached per experiment in `OUT/experiments/<name>.json`, so an interrupted
//! evaluation resumes with the experiments it has not finished. The report (results.json,
//! tables.md, plots, index.html) is then rebuilt from every cached experiment.
//! `docs/RESULTS.md` documents every name that appears in `results.json`.

pub mod altconv;
mod concurrent_env;
pub mod context;
pub mod drape;
pub mod embed;
pub mod guarded;
mod guarded_beam;
mod guarded_limb;
pub mod nnwarp;
pub mod proj;
pub mod sim;
pub(crate) mod study;

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::Context;
use crate::files::copy_tree;

pub use crate::records::{Curve, EnergyBar, ExperimentOutput, LinePlot, Scatter};
pub use concurrent_env::*;
use context::EvalContext;
use weft_data::Size;
use weft_data::files::write_json;

/// Experiments `evaluate` runs, in order.
pub const EXPERIMENTS: [&str; 7] = ["sim", "proj", "embed", "nnwarp", "altconv", "drape", "guarded"];

/// How an evaluation runs: the command line's `cargo xtask evaluate` options.
#[derive(Debug, Clone)]
pub struct EvaluateOptions {
    /// `Quick` (minutes; small meshes) or `Standard` (the committed evaluation).
    pub size: Size,
    /// Run only these experiments (empty: all of [`EXPERIMENTS`]).
    pub only: Vec<String>,
    /// The output directory.
    pub out: PathBuf,
    /// Re-run experiments whose cached output exists in `out/experiments/`.
    pub force: bool,
    /// Hide progress bars.
    pub quiet: bool,
    /// After the run, copy the report (not the large predictions) to this directory with a
    /// `PROVENANCE.md` — how `docs/results/` is made.
    pub publish: Option<PathBuf>,
    /// The command that ran the evaluation, recorded with every experiment.
    pub command: String,
    /// The code version recorded with every experiment and dataset.
    pub code_version: String,
    /// How many independent models an experiment trains at once, each on its share of the
    /// cores (at least 1; see [`EvalContext::concurrently`]).
    pub jobs: usize,
}

impl EvaluateOptions {
    /// The defaults of `cargo xtask evaluate --size SIZE`: every experiment, into
    /// `out/evaluate-SIZE`.
    pub fn new(size: Size) -> Self {
        let out = PathBuf::from(format!("out/evaluate-{}", size.as_str()));
        let defaults = EvalContext::new(size, out.clone());
        Self {
            size,
            only: Vec::new(),
            out,
            force: false,
            quiet: true,
            publish: None,
            command: format!("evaluate --size {size}"),
            code_version: defaults.code_version,
            jobs: defaults.jobs,
        }
    }
}

/// Runs the selected experiments (each resumed from its cached output unless `force`),
/// then rebuilds the report from every experiment cached in `out` at this size, and
/// publishes it if asked.
pub fn run(args: &EvaluateOptions) -> crate::Result<()> {
    let size = args.size;
    if size == Size::Paper {
        return Err(crate::Error::Invalid(
            "evaluate runs at --size quick or standard; paper-size datasets are for training (cargo xtask dataset)"
                .into(),
        ));
    }
    let selected: Vec<&str> = if args.only.is_empty() {
        EXPERIMENTS.to_vec()
    } else {
        for o in &args.only {
            if !EXPERIMENTS.contains(&o.as_str()) {
                return Err(crate::Error::Invalid(format!(
                    "--only {o:?}: experiments are {}",
                    EXPERIMENTS.join(", ")
                )));
            }
        }
        EXPERIMENTS
            .iter()
            .copied()
            .filter(|e| args.only.iter().any(|o| o == e))
            .collect()
    };
    if args.jobs == 0 {
        return Err(crate::Error::Invalid(
            "--jobs 0: at least one model must train at a time".into(),
        ));
    }
    // A published figure must trace to a commit: a build of uncommitted code cannot say
    // which code made it (issue 72).
    if let Some(dest) = &args.publish
        && crate::report::published::is_dirty(&args.code_version)
    {
        return Err(crate::Error::Invalid(format!(
            "--publish {}: this build is of uncommitted code (code version {}); commit, rebuild and rerun, so that \
             PROVENANCE.md can name the commit",
            dest.display(),
            args.code_version
        )));
    }
    let out = args.out.clone();
    std::fs::create_dir_all(out.join("experiments")).with_context(|| format!("creating {}", out.display()))?;
    let ctx = EvalContext {
        size,
        out: out.clone(),
        quiet: args.quiet,
        code_version: args.code_version.clone(),
        jobs: args.jobs,
    };
    let mut ran: Vec<&str> = Vec::new();
    for name in &selected {
        let cache = out.join("experiments").join(format!("{name}.json"));
        if !args.force {
            if let Some(cached) = read_cached(&cache, size)? {
                eprintln!(
                    "{name}: reusing {} ({} records; --force re-runs it)",
                    cache.display(),
                    cached.records.len()
                );
                continue;
            }
        }
        eprintln!("{name}: running ({} size)", size.as_str());
        let t = Instant::now();
        let mut output = match *name {
            "sim" => sim::run(&ctx)?,
            "proj" => proj::run(&ctx)?,
            "embed" => embed::run(&ctx)?,
            "nnwarp" => nnwarp::run(&ctx)?,
            "altconv" => altconv::run(&ctx)?,
            "drape" => drape::run(&ctx)?,
            "guarded" => guarded::run(&ctx)?,
            other => unreachable!("experiment {other} listed but not dispatched"),
        };
        // The experiment may have set the seconds of work it read back from earlier runs.
        output.wall_seconds += t.elapsed().as_secs_f64();
        output.command = format!("cargo xtask {}", args.command);
        output.code_version = args.code_version.clone();
        crate::records::validate(&output.records)?;
        write_json(&cache, &output)?;
        ran.push(name);
        eprintln!(
            "{name}: {} records in {:.1} s{}",
            output.records.len(),
            output.wall_seconds,
            if output.failures.is_empty() {
                String::new()
            } else {
                format!(", {} failure(s) recorded", output.failures.len())
            }
        );
    }
    // Publishing rebuilds the whole published report: an experiment not cached in OUT is
    // taken from the published one (its committed output and renders), so republishing one
    // experiment never drops the others.
    let mut imported: Vec<&str> = Vec::new();
    if let Some(dest) = &args.publish {
        for name in EXPERIMENTS {
            let cache = out.join("experiments").join(format!("{name}.json"));
            let published = dest.join("experiments").join(format!("{name}.json"));
            if cache.exists() || read_cached(&published, size)?.is_none() {
                continue;
            }
            std::fs::copy(&published, &cache).with_context(|| format!("copying {}", published.display()))?;
            let renders = dest.join("renders").join(name);
            if renders.exists() && !out.join("renders").join(name).exists() {
                copy_tree(&renders, &out.join("renders").join(name))?;
            }
            eprintln!("{name}: taken from the published {}", published.display());
            imported.push(name);
        }
        // Peer points (report::peers) measured for the published report stay with it.
        if dest.join("peers").exists() && !out.join("peers").exists() {
            copy_tree(&dest.join("peers"), &out.join("peers"))?;
            eprintln!("peers: taken from the published {}", dest.join("peers").display());
        }
    }
    // The report covers every experiment cached in OUT at this size.
    let mut outputs = Vec::new();
    for name in EXPERIMENTS {
        let cache = out.join("experiments").join(format!("{name}.json"));
        if let Some(o) = read_cached(&cache, size)? {
            outputs.push(o);
        }
    }
    crate::report::write(&out, size, &outputs)?;
    eprintln!(
        "report: {} (results.json, tables.md, plots/, predictions/, renders/)",
        out.join("index.html").display()
    );
    if let Some(dest) = &args.publish {
        publish(&out, dest, &ran, &imported, &outputs, args)?;
        eprintln!("published to {}", dest.display());
    }
    Ok(())
}

/// Copies the report to `dest` with its provenance: the command, and which experiments it
/// ran and which it took from earlier runs cached in the same output directory.
fn publish(
    out: &Path,
    dest: &Path,
    ran: &[&str],
    imported: &[&str],
    outputs: &[ExperimentOutput],
    args: &EvaluateOptions,
) -> crate::Result<()> {
    let reused: Vec<&str> = outputs
        .iter()
        .map(|o| o.experiment.as_str())
        .filter(|e| !ran.contains(e) && !imported.contains(e))
        .collect();
    for sub in ["plots", "renders", "experiments", "peers"] {
        let _ = std::fs::remove_dir_all(dest.join(sub));
    }
    std::fs::create_dir_all(dest)?;
    for f in ["results.json", "tables.md", "index.html"] {
        std::fs::copy(out.join(f), dest.join(f)).with_context(|| format!("copying {f}"))?;
    }
    // The experiments' outputs travel with the report, so any later publication can
    // rebuild it whole (the large predictions stay behind).
    for sub in ["plots", "renders", "experiments", "peers"] {
        // An evaluation without renders (or plots, or peers) has no such directory.
        if out.join(sub).exists() {
            copy_tree(&out.join(sub), &dest.join(sub))?;
        }
    }
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let list = |v: &[&str]| {
        if v.is_empty() {
            "none".to_string()
        } else {
            v.iter().map(|e| format!("`{e}`")).collect::<Vec<_>>().join(", ")
        }
    };
    let text = format!(
        "# Provenance\n\nProduced by\n\n```sh\ncargo xtask {}\n```\n\nExperiments it ran: {}. Experiments it reused from \
         `{}/experiments/`, where earlier runs of `cargo xtask evaluate` with the same `--out` left them: {} \
         (each experiment's wall time is at the top of `tables.md`; `--only NAME --force` reruns one). \
         Machine: {cores} cores of {cpu}. Published by code version `{}` (a build of committed code: \
         `--publish` refuses any other). `index.html` is the whole report in one file. The predictions (every method's positions beside the reference) are not committed: the same \
         command writes them to `{}/predictions/`.\n",
        args.command,
        list(ran),
        out.display(),
        list(&reused),
        args.code_version,
        out.display()
    ) + &if imported.is_empty() {
        String::new()
    } else {
        format!(
            "\nExperiments taken from the report published here before (its `experiments/` outputs, unchanged): {}.\n",
            list(imported)
        )
    } + &provenance_per_experiment(outputs)
        + &stale_list(outputs);
    Ok(weft_data::files::write_text(&dest.join("PROVENANCE.md"), &text)?)
}

/// One line per experiment: the command and code version that produced it.
fn provenance_per_experiment(outputs: &[ExperimentOutput]) -> String {
    let mut s = String::from("\nPer experiment:\n\n");
    for o in outputs {
        if o.command.is_empty() {
            s.push_str(&format!(
                "- `{}` ({:.0} s): its command was not recorded (cached before commands were)\n",
                o.experiment, o.wall_seconds
            ));
        } else {
            s.push_str(&format!(
                "- `{}` ({:.0} s): `{}`, code version {}\n",
                o.experiment, o.wall_seconds, o.command, o.code_version
            ));
        }
    }
    s
}

/// The experiments due for republication (`report::published::stale`), if any.
fn stale_list(outputs: &[ExperimentOutput]) -> String {
    let stale = crate::report::published::stale(outputs);
    if stale.is_empty() {
        return String::new();
    }
    let mut s = String::from(
        "\nStale, due for republication (made before `--publish` required committed code and learned \
         experiments wrote per-seed records; `cargo xtask check-report --published` lists the same):\n\n",
    );
    for e in stale {
        s.push_str(&format!("- {e}\n"));
    }
    s
}

fn read_cached(path: &Path, size: Size) -> crate::Result<Option<ExperimentOutput>> {
    if !path.exists() {
        return Ok(None);
    }
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    match serde_json::from_slice::<ExperimentOutput>(&bytes) {
        Ok(o) if o.size == size => Ok(Some(o)),
        Ok(o) => Err(crate::Error::Invalid(format!(
            "{} holds a {} evaluation; use another --out for {} or pass --force",
            path.display(),
            o.size.as_str(),
            size.as_str()
        ))),
        // An output of an older format is recomputed rather than trusted.
        Err(_) => Ok(None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The published report rebuilt from its own experiment outputs
    /// (`docs/results/experiments/*.json`) is the committed one: `results.json` byte for
    /// byte and `tables.md` but for the assembly time in its first paragraph. Restructuring
    /// the experiments, the records or the report cannot change a published figure without
    /// failing here. (An experiment not published yet is left out, as the published report
    /// leaves it out; `check-report --published` lists it.)
    #[test]
    fn the_published_report_rebuilds_from_its_experiment_outputs_unchanged() {
        let published = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/results");
        let outputs: Vec<crate::records::ExperimentOutput> = EXPERIMENTS
            .iter()
            .map(|e| published.join("experiments").join(format!("{e}.json")))
            .filter(|p| p.exists())
            .map(|p| serde_json::from_slice(&std::fs::read(p).unwrap()).unwrap())
            .collect();
        assert!(outputs.len() >= 6, "the six papers' experiments are published");
        let dir = std::env::temp_dir().join(format!("weft-rebuild-published-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        // The renders are the experiments' images, which the page embeds; the peers are
        // points measured outside the evaluation.
        for sub in ["peers", "renders"] {
            if published.join(sub).exists() {
                crate::files::copy_tree(&published.join(sub), &dir.join(sub)).unwrap();
            }
        }
        crate::report::write(&dir, Size::Standard, &outputs).unwrap();
        let read = |d: &std::path::Path, f: &str| std::fs::read_to_string(d.join(f)).unwrap();
        assert!(
            read(&dir, "results.json") == read(&published, "results.json"),
            "results.json rebuilt from docs/results/experiments differs from the committed one"
        );
        // The first paragraph names the seconds the report took to assemble.
        let body = |t: String| t.split_once("## ").map(|(_, b)| b.to_string()).unwrap_or_default();
        let (rebuilt, committed) = (body(read(&dir, "tables.md")), body(read(&published, "tables.md")));
        if rebuilt != committed {
            let line = rebuilt.lines().zip(committed.lines()).position(|(a, b)| a != b);
            panic!("tables.md rebuilt differs from the committed one at body line {line:?}");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
