//! A training run's progress on the terminal: a bar over its batches and its epoch lines.

use indicatif::ProgressBar;

use weft_data::files::progress_bar;

/// A training run's progress: a bar over its batches (on a terminal) and its epoch lines
/// above it — or, off a terminal where indicatif hides the bar, on standard error. With
/// `quiet`, neither (the lines are in the run's `train.log` all the same).
#[derive(Debug)]
pub struct TrainProgress {
    bar: ProgressBar,
    quiet: bool,
}

impl TrainProgress {
    pub fn new(quiet: bool, prefix: &str) -> crate::Result<Self> {
        Ok(Self {
            bar: progress_bar(quiet, 0, prefix, "batches")?,
            quiet,
        })
    }
}

impl weft_nn::trainer::Observer for TrainProgress {
    fn start(&mut self, batches: u64) {
        self.bar.set_length(batches);
        self.bar.set_position(0);
    }

    fn batch(&mut self, epoch: usize, loss: f64) {
        self.bar.set_message(format!("epoch {} loss {loss:.3e}", epoch + 1));
        self.bar.inc(1);
    }

    fn epoch(&mut self, line: &str) {
        if self.quiet {
            return;
        }
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
    }
}
