//! The environment models trained at once run faster under, and the re-execution of the
//! evaluation command under it. It does not choose how many models train at once
//! ([`super::EvaluateOptions::jobs`] does).

use crate::{Error, Result};

/// The environment that models trained at once run faster under, read by candle and
/// mimalloc once, at their start: candle's elementwise pool (its threads spin between calls
/// and its calls queue on one lock, which models training at once take turns on), and
/// mimalloc's return of freed memory to the kernel (each model's large buffers would be
/// page-faulted back in; the process keeps its peak instead). Two `embed` models on two
/// cores: a median epoch of 7.95 s without, 5.4 s with both (docs/BENCHMARKS.md,
/// `benches/concurrent_env.sh`).
pub const CONCURRENT_ENV: [(&str, &str); 2] = [("CANDLE_NUM_THREADS", "1"), ("MIMALLOC_PURGE_DELAY", "-1")];

/// The variables of [`CONCURRENT_ENV`] to set before `jobs` models (default: one per of
/// `cores`) train at once: none with one job, or when the user set either variable.
pub fn concurrent_env_to_set(
    jobs: Option<usize>,
    cores: usize,
    is_set: impl Fn(&str) -> bool,
) -> Vec<(&'static str, &'static str)> {
    let unset: Vec<_> = CONCURRENT_ENV.into_iter().filter(|(k, _)| !is_set(k)).collect();
    if jobs.unwrap_or(cores) <= 1 || unset.len() < CONCURRENT_ENV.len() {
        return Vec::new();
    }
    unset
}

/// With more than one job, re-executes this command (the same process, `exec`) under
/// [`CONCURRENT_ENV`] unless it already runs under it or the user set those variables;
/// returns only if nothing is to be done (or not on Unix).
pub fn reexec_for_concurrent_jobs(jobs: Option<usize>) -> Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let unset = concurrent_env_to_set(jobs, cores, |k| std::env::var_os(k).is_some());
    if unset.is_empty() {
        return Ok(());
    }
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        let exe = std::env::current_exe().map_err(|source| Error::Exec {
            what: "finding this executable to re-run it".into(),
            source,
        })?;
        let source = std::process::Command::new(&exe)
            .args(std::env::args_os().skip(1))
            .envs(unset)
            .exec();
        Err(Error::Exec {
            what: format!("re-running {} with {CONCURRENT_ENV:?}", exe.display()),
            source,
        })
    }
    #[cfg(not(unix))]
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_environment_is_set_for_several_jobs_unless_the_user_chose() {
        let none = |_: &str| false;
        assert_eq!(concurrent_env_to_set(Some(2), 1, none), CONCURRENT_ENV);
        assert_eq!(concurrent_env_to_set(None, 4, none), CONCURRENT_ENV);
        assert!(concurrent_env_to_set(Some(1), 4, none).is_empty());
        assert!(concurrent_env_to_set(None, 1, none).is_empty());
        assert!(concurrent_env_to_set(Some(2), 2, |k| k == "CANDLE_NUM_THREADS").is_empty());
        assert!(concurrent_env_to_set(Some(2), 2, |_| true).is_empty());
    }
}
