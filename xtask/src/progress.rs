//! A training command's progress on the terminal: a bar over the batches of the current
//! epoch and the epoch lines above it — or, off a terminal where indicatif hides the bar,
//! on standard error. With `quiet`, neither (the lines are in the model's `train.log` all
//! the same). One model trains per command, so there is one bar.

use indicatif::ProgressBar;

/// Shows a `weft_nn::trainer::Trainer` run (see the module documentation).
#[derive(Debug)]
pub struct TrainProgress {
    bar: ProgressBar,
    quiet: bool,
}

impl TrainProgress {
    pub fn new(quiet: bool, prefix: &str) -> anyhow::Result<Self> {
        let bar = weft_data::files::progress_bar(quiet, 0, prefix, "batches")?;
        Ok(Self { bar, quiet })
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
        } else if self.bar.is_hidden() {
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
