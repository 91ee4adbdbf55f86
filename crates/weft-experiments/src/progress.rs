//! A training run's progress on the terminal: a bar over its batches and its epoch lines.

use std::sync::OnceLock;

use indicatif::{MultiProgress, ProgressBar};

use weft_data::files::progress_bar;

/// A training run's progress: a bar over its batches (on a terminal) and its epoch lines
/// above it — or, off a terminal where indicatif hides the bar, on standard error. With
/// `quiet`, neither (the lines are in the run's `train.log` all the same).
///
/// Models trained at once ([`crate::evaluate::context::EvalContext::concurrently`]) each
/// have a bar, stacked rather than drawn over each other, and their epoch lines carry the
/// model's tag.
#[derive(Debug)]
pub struct TrainProgress {
    bar: ProgressBar,
    quiet: bool,
    tag: Option<String>,
}

/// Every training bar of the process, stacked.
fn bars() -> &'static MultiProgress {
    static BARS: OnceLock<MultiProgress> = OnceLock::new();
    BARS.get_or_init(MultiProgress::new)
}

impl TrainProgress {
    pub fn new(quiet: bool, prefix: &str) -> crate::Result<Self> {
        let bar = progress_bar(quiet, 0, prefix, "batches")?;
        Ok(Self {
            // A quiet bar stays hidden: one added to the stack would draw.
            bar: if quiet { bar } else { bars().add(bar) },
            quiet,
            tag: None,
        })
    }

    /// Epoch lines start with `[tag]`, naming the model among others training at once.
    pub fn tagged(mut self, tag: impl Into<String>) -> Self {
        self.tag = Some(tag.into());
        self
    }
}

impl weft_nn::trainer::Observer for TrainProgress {
    fn start(&mut self, batches: u64) {
        self.bar.set_length(batches);
        self.bar.set_position(0);
    }

    fn batch(&mut self, epoch: usize, loss: f64) {
        // A job timing something alone holds the next batch back (`timed_alone`).
        crate::evaluate::context::pause_point();
        self.bar.set_message(format!("epoch {} loss {loss:.3e}", epoch + 1));
        self.bar.inc(1);
    }

    fn epoch(&mut self, line: &str) {
        if self.quiet {
            return;
        }
        let line = match &self.tag {
            Some(tag) => format!("[{tag}] {line}"),
            None => line.to_string(),
        };
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
        if !self.quiet {
            bars().remove(&self.bar);
        }
    }
}
