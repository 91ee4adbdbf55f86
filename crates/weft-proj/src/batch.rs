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

/// Per-example warm starts of a projection layer used in training: the last solution (or
/// what a warm start needs of it) found for each example key. The minimiser does not
/// depend on the start unless the problem has several minima, so a stale or missing entry
/// costs iterations, never answers. Shared by the candle ops and the Python layers.
#[derive(Debug)]
pub struct WarmStarts<K, S>(std::sync::Mutex<std::collections::HashMap<K, S>>);

impl<K, S> Default for WarmStarts<K, S> {
    fn default() -> Self {
        Self(std::sync::Mutex::default())
    }
}

impl<K: std::hash::Hash + Eq + Copy + Ord, S: Clone> WarmStarts<K, S> {
    /// The map; a lock poisoned by a panicking caller still holds valid starts.
    fn map(&self) -> std::sync::MutexGuard<'_, std::collections::HashMap<K, S>> {
        self.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The stored start of each of `keys` (none without keys: a cold batch of `n`).
    pub fn starts(&self, keys: Option<&[K]>, n: usize) -> Vec<Option<S>> {
        match keys {
            Some(keys) => {
                let map = self.map();
                keys.iter().map(|k| map.get(k).cloned()).collect()
            }
            None => vec![None; n],
        }
    }

    /// Remembers `values[b]` for `keys[b]` (nothing without keys).
    pub fn remember(&self, keys: Option<&[K]>, values: impl Iterator<Item = S>) {
        if let Some(keys) = keys {
            let mut map = self.map();
            for (k, v) in keys.iter().zip(values) {
                map.insert(*k, v);
            }
        }
    }

    /// The keys with a stored start, ascending.
    pub fn keys(&self) -> Vec<K> {
        let mut k: Vec<K> = self.map().keys().copied().collect();
        k.sort_unstable();
        k
    }

    /// Forgets every start.
    pub fn clear(&self) {
        self.map().clear();
    }
}

/// `forward(pred, start)` over a batch in parallel, after checking there is one start
/// (possibly none) per prediction: every entry is an error naming the mismatch otherwise.
pub(crate) fn forward_batch_from<P: AsRef<[f64]> + Sync, S: Sync, T: Send>(
    preds: &[P],
    starts: &[Option<S>],
    forward: impl Fn(&[f64], Option<&S>) -> Result<T> + Sync,
) -> Vec<Result<T>> {
    use rayon::prelude::*;
    if preds.len() != starts.len() {
        return (0..preds.len().max(1))
            .map(|_| {
                Err(Error::LengthMismatch {
                    what: "batch warm starts",
                    expected: preds.len(),
                    got: starts.len(),
                })
            })
            .collect();
    }
    preds
        .par_iter()
        .zip(starts)
        .map(|(p, s)| forward(p.as_ref(), s.as_ref()))
        .collect()
}
