//! What the experiments share: their [`EvalContext`], the datasets they generate (or
//! complete) under the evaluation's directory with the ground truth's cost per frame, and
//! the opening of every experiment's `score_model` ([`Scoring`]).

use std::path::{Path, PathBuf};

use weft_data::Size;

use crate::error::Context;
use crate::records::ExperimentOutput;

/// What every experiment of a run shares: the size, where it writes, whether it shows
/// progress, and the code version its datasets' manifests record.
#[derive(Debug, Clone)]
pub struct EvalContext {
    pub size: Size,
    /// The evaluation's output directory; an experiment writes under `out/<name>/`.
    pub out: PathBuf,
    pub quiet: bool,
    pub code_version: String,
    /// How many independent models an experiment may train at once (`evaluate --jobs`;
    /// default one per core), each on an equal share of the cores: see
    /// [`EvalContext::concurrently`].
    pub jobs: usize,
}

impl EvalContext {
    /// A context writing under `out` with the defaults of `cargo xtask evaluate`: progress
    /// shown, one job per core.
    pub fn new(size: Size, out: PathBuf) -> Self {
        Self {
            size,
            out,
            quiet: false,
            code_version: concat!("weft-experiments ", env!("CARGO_PKG_VERSION")).to_string(),
            jobs: rayon::current_num_threads(),
        }
    }

    /// How many of `n` independent jobs [`concurrently`](Self::concurrently) runs at once:
    /// [`jobs`](Self::jobs), but at least one and at most `n`.
    pub fn workers(&self, n: usize) -> usize {
        self.jobs.clamp(1, n.max(1))
    }

    /// Runs `job(0)`, …, `job(n − 1)`, which must not depend on each other, up to
    /// [`workers(n)`](Self::workers) at once, each in its own rayon pool with an equal share of the
    /// current pool's threads; returns their results in index order, or the first error
    /// (by index) once every job has stopped, so no job is cut off mid-way.
    ///
    /// Why: a model's training is dominated by products with weight matrices too large for
    /// the caches, which scale poorly across threads. On two cores, two embedding models
    /// trained on one core each finish about 1.6× sooner than the same two trained one
    /// after the other on both (docs/BENCHMARKS.md). A job's results depend on its pool's
    /// size (kernels split their sums by thread), never on the jobs beside it; with one
    /// job at a time the jobs run in the current pool, as they did before.
    ///
    /// Two process-wide facilities slow models that share a process (candle's elementwise
    /// pool and mimalloc's purging; docs/BENCHMARKS.md, "In one process"). `cargo xtask
    /// evaluate` sets both for its process when `jobs > 1`; a library caller that wants the
    /// same speed sets `CANDLE_NUM_THREADS=1` and `MIMALLOC_PURGE_DELAY=-1` before starting.
    /// The results are the same either way.
    pub fn concurrently<T: Send>(
        &self,
        n: usize,
        job: impl Fn(usize) -> crate::Result<T> + Sync,
    ) -> crate::Result<Vec<T>> {
        use std::sync::atomic::{AtomicUsize, Ordering};
        use std::sync::{Mutex, PoisonError};
        let workers = self.workers(n);
        if workers == 1 {
            return (0..n).map(job).collect();
        }
        let threads = (rayon::current_num_threads() / workers).max(1);
        let next = AtomicUsize::new(0);
        let results: Vec<Mutex<Option<crate::Result<T>>>> = (0..n).map(|_| Mutex::new(None)).collect();
        std::thread::scope(|s| {
            for _ in 0..workers {
                s.spawn(|| {
                    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= n {
                            break;
                        }
                        let result = match &pool {
                            Ok(pool) => pool.install(|| job(i)),
                            Err(e) => Err(crate::Error::Failed(format!(
                                "a {threads}-thread pool for job {i}: {e}"
                            ))),
                        };
                        *results[i].lock().unwrap_or_else(PoisonError::into_inner) = Some(result);
                    }
                });
            }
        });
        results
            .into_iter()
            .enumerate()
            .map(|(i, r)| {
                r.into_inner()
                    .unwrap_or_else(PoisonError::into_inner)
                    .unwrap_or_else(|| Err(crate::Error::Failed(format!("job {i} did not run"))))
            })
            .collect()
    }
}

/// Generates `scene`'s dataset into `dir`, or completes one an interrupted run left there
/// (the generator rewrites its manifest after every sequence, so a manifest alone does
/// not mean the dataset is whole). Returns the sequences that stopped early — a solve
/// that did not converge; their frames up to it are stored and used — for the
/// experiment's failures, on every run that reads the dataset.
pub fn generate_dataset(ctx: &EvalContext, scene: &str, dir: &Path) -> crate::Result<Vec<String>> {
    generate_dataset_frames(ctx, scene, dir, None)
}

/// [`generate_dataset`] with the size's frames per sequence overridden.
pub fn generate_dataset_frames(
    ctx: &EvalContext,
    scene: &str,
    dir: &Path,
    frames: Option<usize>,
) -> crate::Result<Vec<String>> {
    let manifest = dir.join("manifest.json");
    let exists = manifest.exists();
    if exists {
        let m = weft_data::read_manifest(&manifest)?;
        if m.is_complete() {
            return Ok(stopped_early(scene, &m));
        }
    }
    let mut spec = weft_data::DatasetSpec::new(scene, ctx.size)?;
    if let Some(f) = frames {
        spec.frames = f;
    }
    let options = weft_data::GenerateOptions {
        resume: exists,
        quiet: true,
        code_version: ctx.code_version.clone(),
        ..Default::default()
    };
    // Sequences that stopped early are stored up to the failure: the experiment uses them
    // and reports which.
    Ok(stopped_early(scene, &weft_data::generate(&spec, dir, &options)?))
}

fn stopped_early(scene: &str, m: &weft_data::Manifest) -> Vec<String> {
    m.stopped_early()
        .into_iter()
        .map(|l| format!("{scene} dataset: {l}"))
        .collect()
}

/// Ground-truth solver seconds per frame of a dataset (its `timing.json`).
pub fn ground_truth_seconds(dir: &Path) -> crate::Result<f64> {
    let t: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("timing.json"))?)?;
    let (mut frames, mut seconds) = (0.0, 0.0);
    for v in t["sequences"]
        .as_object()
        .context("timing.json lists no sequences")?
        .values()
    {
        frames += v[0].as_f64().unwrap_or(0.0);
        seconds += v[1].as_f64().unwrap_or(0.0);
    }
    crate::error::ensure!(frames > 0.0, "timing.json counts no frames");
    Ok(seconds / frames)
}

/// What every experiment's `score_model` is given and opens with (`crate::score` builds it
/// and dispatches on the model kind):
/// the model loaded with its directory named in any error, the split checked for
/// something to score, the dataset's ground-truth cost per frame where it recorded one,
/// and the output begun with a note saying what was scored on what.
#[derive(Debug, Clone, Copy)]
pub struct Scoring<'a> {
    pub ctx: &'a EvalContext,
    /// The records' experiment name.
    pub experiment: &'a str,
    pub model_dir: &'a Path,
    pub data_dir: &'a Path,
    pub split: &'a str,
}

impl Scoring<'_> {
    /// `load(model_dir)`, its error naming the directory.
    pub fn load_model<M, E: Into<crate::Error>>(
        &self,
        load: impl FnOnce(&Path) -> std::result::Result<M, E>,
    ) -> crate::Result<M> {
        load(self.model_dir).with_context(|| format!("loading the model in {}", self.model_dir.display()))
    }

    /// An error unless the split holds `count > 0` of `what` (examples, sequences).
    pub fn require(&self, count: usize, what: &str) -> crate::Result<()> {
        crate::error::ensure!(count > 0, "{} has no {} {what}", self.data_dir.display(), self.split);
        Ok(())
    }

    /// The dataset's ground-truth seconds per frame, if its `timing.json` says.
    pub fn ground_truth_seconds(&self) -> Option<f64> {
        ground_truth_seconds(self.data_dir).ok()
    }

    /// The output, its first note `"<experiment> score: <model directory> <on>"`.
    pub fn output(&self, on: impl std::fmt::Display) -> ExperimentOutput {
        let mut out = ExperimentOutput::new(self.experiment, self.ctx.size);
        out.notes
            .push(format!("{} score: {} {on}", self.experiment, self.model_dir.display()));
        out
    }
}

/// Taken for reading, briefly, at every training batch ([`pause_point`]) and for writing
/// by a timed section ([`timed_alone`]): a model training beside a timed one waits at its
/// next batch.
static TIMED: std::sync::RwLock<()> = std::sync::RwLock::new(());

/// Where a training run waits while another job of the process times something
/// ([`timed_alone`]); called by the training observer at every batch.
pub fn pause_point() {
    drop(TIMED.read().unwrap_or_else(std::sync::PoisonError::into_inner));
}

/// Runs `f` — a section whose wall time is reported — alone: every model training in the
/// process waits at its next batch until it returns, and `f` runs on a pool of all the
/// cores, as it would with one job. Without it, a model timed while another trains beside
/// it ([`EvalContext::concurrently`]) reports the time of one core shared with that
/// training. Timed sections of several jobs take turns.
pub fn timed_alone<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    static FULL: std::sync::OnceLock<Option<rayon::ThreadPool>> = std::sync::OnceLock::new();
    let _alone = TIMED.write().unwrap_or_else(std::sync::PoisonError::into_inner);
    let full = FULL.get_or_init(|| {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        rayon::ThreadPoolBuilder::new().num_threads(cores).build().ok()
    });
    match full {
        Some(pool) => pool.install(f),
        None => f(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// Jobs return in index order, each inside a pool of its share of the threads; a
    /// failing job does not stop the others, and the first error by index is returned once
    /// all have run. One job at a time runs in the caller's pool.
    #[test]
    fn concurrent_jobs_share_the_threads_keep_their_order_and_all_run_before_an_error() {
        let four = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap();
        let ctx = |jobs| EvalContext {
            jobs,
            ..EvalContext::new(Size::Quick, PathBuf::from("unused"))
        };
        let threads = |jobs| {
            four.install(|| ctx(jobs).concurrently(5, |i| Ok((i, rayon::current_num_threads()))))
                .unwrap()
        };
        assert_eq!(threads(2), (0..5).map(|i| (i, 2)).collect::<Vec<_>>());
        assert_eq!(threads(3), (0..5).map(|i| (i, 1)).collect::<Vec<_>>());
        assert_eq!(threads(1), (0..5).map(|i| (i, 4)).collect::<Vec<_>>());
        // More workers than jobs: as many as there are jobs; no jobs or no workers: one.
        assert_eq!(
            [
                ctx(8).workers(2),
                ctx(2).workers(6),
                ctx(0).workers(3),
                ctx(2).workers(0)
            ],
            [2, 2, 1, 1]
        );
        let two = four.install(|| ctx(8).concurrently(2, |_| Ok(rayon::current_num_threads())));
        assert_eq!(two.unwrap(), vec![2, 2]);
        let ran = AtomicUsize::new(0);
        let failed = ctx(2).concurrently(6, |i| {
            ran.fetch_add(1, Ordering::Relaxed);
            if i == 1 || i == 4 {
                Err(crate::Error::Failed(format!("job {i} failed")))
            } else {
                Ok(i)
            }
        });
        assert_eq!(ran.load(Ordering::Relaxed), 6, "every job ran");
        assert_eq!(
            failed.unwrap_err().to_string(),
            crate::Error::Failed("job 1 failed".into()).to_string()
        );
        assert!(ctx(2).concurrently(0, Ok).unwrap().is_empty());
    }

    /// A timed section holds every training batch back until it returns, and runs on all
    /// the cores even when called from a one-thread pool.
    #[test]
    fn a_timed_section_pauses_training_and_gets_every_core() {
        let batches = AtomicUsize::new(0);
        let stop = std::sync::atomic::AtomicBool::new(false);
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        std::thread::scope(|s| {
            s.spawn(|| {
                while !stop.load(Ordering::Relaxed) {
                    pause_point();
                    batches.fetch_add(1, Ordering::Relaxed);
                }
            });
            // Let the "training" run, then time a section from a one-thread pool.
            while batches.load(Ordering::Relaxed) < 100 {
                std::thread::yield_now();
            }
            let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
            let (during, threads) = one.install(|| {
                timed_alone(|| {
                    let before = batches.load(Ordering::Relaxed);
                    std::thread::sleep(std::time::Duration::from_millis(50));
                    (batches.load(Ordering::Relaxed) - before, rayon::current_num_threads())
                })
            });
            // One batch may have been past its pause point when the section began.
            assert!(during <= 1, "{during} batches ran during the timed section");
            assert_eq!(threads, cores);
            let after = batches.load(Ordering::Relaxed);
            while batches.load(Ordering::Relaxed) < after + 100 {
                std::thread::yield_now();
            }
            stop.store(true, Ordering::Relaxed);
        });
    }
}
