//! `cargo xtask evaluate`: every method against its reference, speed beside accuracy.
//!
//! Each experiment (`sim`, `proj`, `embed`, `nnwarp`, `altconv`, `drape`) runs its methods and a tight
//! reference in one process, so time ratios compare one machine state, and returns an
//! [`ExperimentOutput`]: tidy [`Record`]s, roll-out curves, energies and renders. Outputs
//! are cached per experiment in `OUT/experiments/<name>.json`, so an interrupted
//! evaluation resumes with the experiments it has not finished. The report (results.json,
//! tables.md, plots, index.html) is then rebuilt from every cached experiment.
//! `docs/RESULTS.md` documents every name that appears in `results.json`.

pub mod altconv;
pub mod drape;
pub mod embed;
pub mod nnwarp;
pub mod paper;
pub mod proj;
pub mod results;
pub mod sim;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;

pub use results::{Curve, EnergyBar, ExperimentOutput, LinePlot, Scatter};
use weft_data::Size;
use weft_data::files::write_json;

/// Experiments `evaluate` runs, in order.
pub const EXPERIMENTS: [&str; 6] = ["sim", "proj", "embed", "nnwarp", "altconv", "drape"];

#[derive(Args)]
pub struct EvaluateArgs {
    /// quick (minutes; small meshes) or standard (the committed evaluation in docs/results/).
    #[arg(long, default_value_t = Size::Standard)]
    size: Size,
    /// Shorthand for --size quick.
    #[arg(long)]
    quick: bool,
    /// Run only these experiments (comma-separated): sim, proj, embed, nnwarp, altconv, drape.
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// Output directory (default: out/evaluate-<size>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Re-run experiments whose cached output exists in OUT/experiments/ (default: resume, reusing them).
    #[arg(long)]
    force: bool,
    /// Hide progress bars.
    #[arg(long)]
    quiet: bool,
    /// After the run, copy the report (results.json, tables.md, index.html, plots/, renders/; not the large
    /// predictions/) to this directory with a PROVENANCE.md naming the command, machine and code version —
    /// how docs/results/ is made.
    #[arg(long)]
    publish: Option<PathBuf>,
}

/// What an experiment needs from the command line.
pub struct EvalContext {
    pub size: Size,
    pub out: PathBuf,
    pub quiet: bool,
}

pub fn run(args: EvaluateArgs) -> anyhow::Result<()> {
    let size = if args.quick { Size::Quick } else { args.size };
    if size == Size::Paper {
        bail!("evaluate runs at --size quick or standard; paper-size datasets are for training (cargo xtask dataset)");
    }
    let selected: Vec<&str> = if args.only.is_empty() {
        EXPERIMENTS.to_vec()
    } else {
        for o in &args.only {
            if !EXPERIMENTS.contains(&o.as_str()) {
                bail!("--only {o:?}: experiments are {}", EXPERIMENTS.join(", "));
            }
        }
        EXPERIMENTS
            .iter()
            .copied()
            .filter(|e| args.only.iter().any(|o| o == e))
            .collect()
    };
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("out/evaluate-{}", size.as_str())));
    std::fs::create_dir_all(out.join("experiments")).with_context(|| format!("creating {}", out.display()))?;
    let ctx = EvalContext {
        size,
        out: out.clone(),
        quiet: args.quiet,
    };
    let start = Instant::now();
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
            other => unreachable!("experiment {other} listed but not dispatched"),
        };
        output.wall_seconds = t.elapsed().as_secs_f64();
        output.command = format!("cargo xtask {}", std::env::args().skip(1).collect::<Vec<_>>().join(" "));
        output.code_version = crate::code_version();
        results::validate(&output.records)?;
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
    // The report covers every experiment cached in OUT at this size.
    let mut outputs = Vec::new();
    for name in EXPERIMENTS {
        let cache = out.join("experiments").join(format!("{name}.json"));
        if let Some(o) = read_cached(&cache, size)? {
            outputs.push(o);
        }
    }
    crate::report::write(&out, size, &outputs, start.elapsed().as_secs_f64())?;
    println!(
        "report: {} (results.json, tables.md, plots/, predictions/, renders/)",
        out.join("index.html").display()
    );
    if let Some(dest) = &args.publish {
        publish(&out, dest, &ran, &outputs)?;
        println!("published to {}", dest.display());
    }
    Ok(())
}

/// Copies the report to `dest` with its provenance: the command, and which experiments it
/// ran and which it took from earlier runs cached in the same output directory.
/// Mean and (population) standard deviation of `samples`; (0, 0) for none.
pub(crate) fn mean_sd(samples: impl Iterator<Item = f64>) -> (f64, f64) {
    let v: Vec<f64> = samples.collect();
    let n = v.len().max(1) as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

fn publish(out: &Path, dest: &Path, ran: &[&str], outputs: &[ExperimentOutput]) -> anyhow::Result<()> {
    let reused: Vec<&str> = outputs
        .iter()
        .map(|o| o.experiment.as_str())
        .filter(|e| !ran.contains(e))
        .collect();
    for sub in ["plots", "renders"] {
        let _ = std::fs::remove_dir_all(dest.join(sub));
    }
    std::fs::create_dir_all(dest)?;
    for f in ["results.json", "tables.md", "index.html"] {
        std::fs::copy(out.join(f), dest.join(f)).with_context(|| format!("copying {f}"))?;
    }
    for sub in ["plots", "renders"] {
        // An evaluation without renders (or plots) has no such directory.
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
         Machine: {cores} cores of {cpu}; code version {}. `index.html` is the whole report in one file. The predictions (every method's positions beside the reference) are not committed: the same \
         command writes them to `{}/predictions/`.\n",
        std::env::args().skip(1).collect::<Vec<_>>().join(" "),
        list(ran),
        out.display(),
        list(&reused),
        crate::code_version(),
        out.display()
    ) + &provenance_per_experiment(outputs);
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

fn copy_tree(from: &Path, to: &Path) -> anyhow::Result<()> {
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

fn read_cached(path: &Path, size: Size) -> anyhow::Result<Option<ExperimentOutput>> {
    if !path.exists() {
        return Ok(None);
    }
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    match serde_json::from_slice::<ExperimentOutput>(&bytes) {
        Ok(o) if o.size == size => Ok(Some(o)),
        Ok(o) => bail!(
            "{} holds a {} evaluation; use another --out for {} or pass --force",
            path.display(),
            o.size.as_str(),
            size.as_str()
        ),
        // An output of an older format is recomputed rather than trusted.
        Err(_) => Ok(None),
    }
}
