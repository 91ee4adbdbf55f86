//! A training run's progress on the terminal, for any [`Observer`] user that shows one: a
//! bar over the batches of the current epoch and the epoch lines above it — or, off a
//! terminal where indicatif hides the bar, on standard error. With `quiet`, neither (the
//! lines are in the run's `train.log` all the same). It draws and prints; it does not train.

use std::sync::OnceLock;

use indicatif::{MultiProgress, ProgressBar};

use crate::Result;
use crate::trainer::Observer;

/// Shows a [`crate::trainer::Trainer`] run (see the module documentation).
///
/// A lone bar ([`TrainProgress::new`]) is for one model training in the process; models
/// trained at once each take a [`TrainProgress::stacked`] bar, drawn one above the other
/// rather than over each other, and their epoch lines carry the model's tag
/// ([`TrainProgress::tagged`]).
#[derive(Debug)]
pub struct TrainProgress {
    bar: ProgressBar,
    quiet: bool,
    stacked: bool,
    tag: Option<String>,
    before_batch: Option<fn()>,
}

/// Every stacked training bar of the process.
fn bars() -> &'static MultiProgress {
    static BARS: OnceLock<MultiProgress> = OnceLock::new();
    BARS.get_or_init(MultiProgress::new)
}

impl TrainProgress {
    /// A lone bar labelled `prefix` (hidden with `quiet`).
    pub fn new(quiet: bool, prefix: &str) -> Result<Self> {
        Ok(Self {
            bar: weft_data::files::progress_bar(quiet, 0, prefix, "batches")?,
            quiet,
            stacked: false,
            tag: None,
            before_batch: None,
        })
    }

    /// A bar on the process's stack of training bars (hidden with `quiet`).
    pub fn stacked(quiet: bool, prefix: &str) -> Result<Self> {
        let mut progress = Self::new(quiet, prefix)?;
        // A quiet bar stays hidden: one added to the stack would draw.
        if !quiet {
            progress.bar = bars().add(progress.bar.clone());
            progress.stacked = true;
        }
        Ok(progress)
    }

    /// Epoch lines start with `[tag]`, naming the model among others training at once.
    pub fn tagged(mut self, tag: impl Into<String>) -> Self {
        self.tag = Some(tag.into());
        self
    }

    /// Calls `hook` before every batch is shown (a caller that holds training back, e.g.
    /// while another job is timed alone, blocks there).
    pub fn before_each_batch(mut self, hook: fn()) -> Self {
        self.before_batch = Some(hook);
        self
    }

    /// The line shown for an epoch: `line`, after the tag if there is one.
    fn epoch_line(&self, line: &str) -> String {
        match &self.tag {
            Some(tag) => format!("[{tag}] {line}"),
            None => line.to_string(),
        }
    }
}

impl Observer for TrainProgress {
    fn start(&mut self, batches: u64) {
        self.bar.set_length(batches);
        self.bar.set_position(0);
    }

    fn batch(&mut self, epoch: usize, loss: f64) {
        if let Some(hook) = self.before_batch {
            hook();
        }
        self.bar.set_message(format!("epoch {} loss {loss:.3e}", epoch + 1));
        self.bar.inc(1);
    }

    fn epoch(&mut self, line: &str) {
        if self.quiet {
            return;
        }
        let line = self.epoch_line(line);
        if self.bar.is_hidden() {
            eprintln!("{line}");
        } else {
            self.bar.println(line);
        }
    }
}

impl Drop for TrainProgress {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
        if self.stacked {
            bars().remove(&self.bar);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epoch_lines_carry_the_tag_and_a_quiet_bar_stays_off_the_stack() {
        let plain = TrainProgress::new(true, "m").unwrap();
        assert_eq!(plain.epoch_line("epoch 1"), "epoch 1");
        let tagged = TrainProgress::stacked(true, "m").unwrap().tagged("seed-1");
        assert_eq!(tagged.epoch_line("epoch 1"), "[seed-1] epoch 1");
        assert!(!tagged.stacked && tagged.bar.is_hidden());
    }

    #[test]
    fn the_hook_runs_before_every_batch() {
        static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let mut p = TrainProgress::new(true, "m").unwrap().before_each_batch(|| {
            CALLS.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        });
        p.start(2);
        p.batch(0, 1.0);
        p.batch(0, 0.5);
        assert_eq!(CALLS.load(std::sync::atomic::Ordering::SeqCst), 2);
    }
}
