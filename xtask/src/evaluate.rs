//! `cargo xtask evaluate` and `cargo xtask check-report`: argument parsing for
//! weft-experiments' evaluation and report check.

use std::path::PathBuf;

use clap::Args;
use weft_data::Size;
use weft_experiments::evaluate::EvaluateOptions;

#[derive(Args)]
pub struct EvaluateArgs {
    /// quick (minutes; small meshes), standard (the committed evaluation in docs/results/)
    /// or paper (the papers' dataset sizes).
    #[arg(long, default_value_t = Size::Standard)]
    size: Size,
    /// Shorthand for --size quick (not with --size).
    #[arg(long, conflicts_with = "size")]
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
    /// Models trained at once where an experiment has independent ones (the seeds and λ_ephys
    /// candidates of `embed`), each on an equal share of the cores; default one per core.
    /// On 2 cores two models at once finish about 1.6x sooner than one after the other. With
    /// more than one, the command runs with CANDLE_NUM_THREADS=1 and MIMALLOC_PURGE_DELAY=-1
    /// unless either is set (their reasons: docs/BENCHMARKS.md).
    #[arg(long)]
    jobs: Option<usize>,
}

pub fn run(args: EvaluateArgs) -> anyhow::Result<()> {
    weft_experiments::evaluate::reexec_for_concurrent_jobs(args.jobs)?;
    let size = if args.quick { Size::Quick } else { args.size };
    let mut options = EvaluateOptions::new(size);
    if let Some(o) = args.out {
        options.out = o;
    }
    options.only = args.only;
    options.force = args.force;
    options.quiet = args.quiet;
    options.publish = args.publish;
    if let Some(jobs) = args.jobs {
        options.jobs = jobs;
    }
    options.command = std::env::args().skip(1).collect::<Vec<_>>().join(" ");
    options.code_version = crate::version::code_version();
    weft_experiments::evaluate::run(&options)?;
    Ok(())
}

#[derive(Args)]
pub struct CheckArgs {
    /// A directory written by `cargo xtask evaluate`.
    dir: PathBuf,
    /// The directory is a published report (`evaluate --publish`, e.g. `docs/results`): its
    /// `PROVENANCE.md` must exist, and the predictions, which are not committed, are not
    /// required.
    #[arg(long)]
    published: bool,
    /// Also compare every figure (timings aside) with the report in OTHER, e.g. a quick
    /// evaluation run before a change that must not move a figure; fails beyond `--rtol`.
    #[arg(long, value_name = "OTHER")]
    against: Option<PathBuf>,
    /// The relative difference `--against` accepts.
    #[arg(long, default_value_t = 1e-6, requires = "against")]
    rtol: f64,
}

pub fn check(args: CheckArgs) -> anyhow::Result<()> {
    let s = weft_experiments::report::check(&args.dir, args.published)?;
    outln!(
        "{}: {} records, {} plot, render and prediction files — all parse",
        args.dir.display(),
        s.records,
        s.files
    );
    for stale in &s.stale {
        outln!("stale, republish: {stale}");
    }
    if let Some(other) = &args.against {
        anyhow::ensure!(args.rtol >= 0.0, "--rtol {} must be a non-negative number", args.rtol);
        let c = weft_experiments::report::compare::compare(other, &args.dir)?;
        let (largest, cell) = c.largest.clone().unwrap_or((0.0, "none".into()));
        outln!(
            "against {}: {} figures compared, {} differ, largest relative difference {largest:.3e} ({cell}); cells only there: {}, only here: {}",
            other.display(),
            c.compared,
            c.differing,
            c.only_in_first.len(),
            c.only_in_second.len()
        );
        anyhow::ensure!(c.agrees(args.rtol), "the figures differ beyond --rtol {}", args.rtol);
    }
    Ok(())
}
