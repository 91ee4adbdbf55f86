//! A training run's progress on the terminal: weft-nn's [`weft_nn::progress::TrainProgress`]
//! on the stack of bars of models trained at once, held back while a job is timed alone.

/// A training run's progress: a bar over its batches (on a terminal) and its epoch lines
/// above it — or, off a terminal where indicatif hides the bar, on standard error. With
/// `quiet`, neither (the lines are in the run's `train.log` all the same).
///
/// Models trained at once ([`crate::evaluate::context::EvalContext::concurrently`]) each
/// have a bar, stacked rather than drawn over each other, and their epoch lines carry the
/// model's tag.
#[derive(Debug)]
pub struct TrainProgress(weft_nn::progress::TrainProgress);

impl TrainProgress {
    pub fn new(quiet: bool, prefix: &str) -> crate::Result<Self> {
        // A job timing something alone holds the next batch back (`timed_alone`).
        let progress = weft_nn::progress::TrainProgress::stacked(quiet, prefix)?
            .before_each_batch(crate::evaluate::context::pause_point);
        Ok(Self(progress))
    }

    /// Epoch lines start with `[tag]`, naming the model among others training at once.
    pub fn tagged(self, tag: impl Into<String>) -> Self {
        Self(self.0.tagged(tag))
    }
}

impl weft_nn::trainer::Observer for TrainProgress {
    fn start(&mut self, batches: u64) {
        self.0.start(batches);
    }

    fn batch(&mut self, epoch: usize, loss: f64) {
        self.0.batch(epoch, loss);
    }

    fn epoch(&mut self, line: &str) {
        self.0.epoch(line);
    }
}
