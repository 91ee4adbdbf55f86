//! The batch backward shared by both layers: one output gradient per forward solution,
//! examples in parallel.

use crate::error::{Error, Result};

/// `backward(solution, gradient)` over a batch in parallel (rayon over examples), after
/// checking that there is one output gradient per solution — the batch backward of both
/// layers.
pub(crate) fn backward_batch<S: Sync, G: AsRef<[f64]> + Sync, T: Send>(
    solutions: &[S],
    grads: &[G],
    backward: impl Fn(&S, &[f64]) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    use rayon::prelude::*;
    if solutions.len() != grads.len() {
        return Err(Error::LengthMismatch {
            what: "batch gradients",
            expected: solutions.len(),
            got: grads.len(),
        });
    }
    solutions
        .par_iter()
        .zip(grads.par_iter())
        .map(|(s, g)| backward(s, g.as_ref()))
        .collect()
}
