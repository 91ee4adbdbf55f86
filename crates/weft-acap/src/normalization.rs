//! Linear feature scaling into [−0.95, 0.95] for tanh network outputs (docs/ACAP.md §A4).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::features::{Feature, LOG_ROTATION_BLOCK, STRETCH_BLOCK};

/// Per-dimension affine maps `x ↦ 0.95 · (2 (x − min)/(max − min) − 1)`, fitted on a
/// training set and stored with the model.
///
/// [`FeatureNormalization::fit_per_block`] follows the reference autoencoder code
/// (aldehydecho/convMesh `utils.py`): one min/max over the whole log-rotation block and
/// one over the whole stretch block, widened by 1e-6; every dimension of a block then
/// shares the map. [`FeatureNormalization::fit_per_dimension`] is the per-dimension
/// variant of `design.md`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeatureNormalization {
    pub min: [f64; 9],
    pub max: [f64; 9],
}

/// Bound of the normalised range.
pub const NORMALIZED_BOUND: f64 = 0.95;
/// Widening of the fitted range on each side (reference code).
const WIDEN: f64 = 1e-6;

impl FeatureNormalization {
    /// One min/max per block (log R, S) over every feature of every frame.
    pub fn fit_per_block<'a>(features: impl IntoIterator<Item = &'a Feature>) -> Result<Self> {
        let (lo, hi) = min_max(features)?;
        let mut min = [0.0; 9];
        let mut max = [0.0; 9];
        for block in [LOG_ROTATION_BLOCK, STRETCH_BLOCK] {
            let b_lo = block.clone().map(|d| lo[d]).fold(f64::INFINITY, f64::min);
            let b_hi = block.clone().map(|d| hi[d]).fold(f64::NEG_INFINITY, f64::max);
            for d in block {
                min[d] = b_lo - WIDEN;
                max[d] = b_hi + WIDEN;
            }
        }
        Self::from_bounds(min, max)
    }

    /// One min/max per feature dimension.
    pub fn fit_per_dimension<'a>(features: impl IntoIterator<Item = &'a Feature>) -> Result<Self> {
        let (lo, hi) = min_max(features)?;
        Self::from_bounds(lo.map(|v| v - WIDEN), hi.map(|v| v + WIDEN))
    }

    /// From stored bounds (e.g. loaded with a model); checks they are finite and ordered.
    pub fn from_bounds(min: [f64; 9], max: [f64; 9]) -> Result<Self> {
        for d in 0..9 {
            for (what, value) in [("minimum", min[d]), ("maximum", max[d])] {
                if !value.is_finite() {
                    return Err(Error::NonFiniteNormalization { what, value });
                }
            }
            if max[d] <= min[d] {
                return Err(Error::InvalidSettings(format!(
                    "normalisation dimension {d}: maximum {} must exceed minimum {}",
                    max[d], min[d]
                )));
            }
        }
        Ok(Self { min, max })
    }

    /// `d(denormalised)/d(normalised)` per dimension, for chaining gradients through
    /// [`FeatureNormalization::denormalize`].
    pub fn scale(&self) -> [f64; 9] {
        std::array::from_fn(|d| (self.max[d] - self.min[d]) / (2.0 * NORMALIZED_BOUND))
    }

    pub fn normalize(&self, f: &Feature) -> Feature {
        std::array::from_fn(|d| NORMALIZED_BOUND * (2.0 * (f[d] - self.min[d]) / (self.max[d] - self.min[d]) - 1.0))
    }

    pub fn denormalize(&self, f: &Feature) -> Feature {
        std::array::from_fn(|d| self.min[d] + (f[d] / NORMALIZED_BOUND + 1.0) * 0.5 * (self.max[d] - self.min[d]))
    }

    pub fn normalize_all(&self, features: &[Feature]) -> Vec<Feature> {
        features.iter().map(|f| self.normalize(f)).collect()
    }

    pub fn denormalize_all(&self, features: &[Feature]) -> Vec<Feature> {
        features.iter().map(|f| self.denormalize(f)).collect()
    }
}

fn min_max<'a>(features: impl IntoIterator<Item = &'a Feature>) -> Result<([f64; 9], [f64; 9])> {
    let mut lo = [f64::INFINITY; 9];
    let mut hi = [f64::NEG_INFINITY; 9];
    let mut count = 0usize;
    for f in features {
        for d in 0..9 {
            if !f[d].is_finite() {
                return Err(Error::NonFiniteNormalization {
                    what: "training feature",
                    value: f[d],
                });
            }
            lo[d] = lo[d].min(f[d]);
            hi[d] = hi[d].max(f[d]);
        }
        count += 1;
    }
    if count == 0 {
        return Err(Error::EmptyTrainingSet);
    }
    Ok((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;
    use weft_testkit::{TestRng, assert_close};

    fn random_features(seed: u64, n: usize) -> Vec<Feature> {
        let mut rng = TestRng::new(seed);
        (0..n)
            .map(|_| {
                let mut f = [0.0; 9];
                for (d, v) in f.iter_mut().enumerate() {
                    *v = if d < 3 {
                        rng.uniform(-4.0, 7.0)
                    } else {
                        rng.uniform(0.5, 1.6) * (d as f64)
                    };
                }
                f
            })
            .collect()
    }

    #[test]
    fn per_block_shares_bounds_within_a_block_and_maps_into_range() {
        let data = random_features(1, 500);
        let norm = FeatureNormalization::fit_per_block(&data).unwrap();
        assert!(norm.min[0] == norm.min[1] && norm.min[1] == norm.min[2]);
        assert!(norm.max[3] == norm.max[8] && norm.min[3] == norm.min[7]);
        assert!(norm.min[0] != norm.min[3]);
        let mut hit_top = 0.0f64;
        for f in &data {
            let g = norm.normalize(f);
            for v in g {
                assert!((-NORMALIZED_BOUND..=NORMALIZED_BOUND).contains(&v), "{v} outside ±0.95");
                hit_top = hit_top.max(v.abs());
            }
        }
        // The extreme training value lands at ±0.95 up to the 1e-6 widening.
        assert_close!(hit_top, NORMALIZED_BOUND, rtol = 0.0, atol = 1e-5);
    }

    #[test]
    fn round_trip_and_scale_are_consistent() {
        let data = random_features(2, 100);
        for norm in [
            FeatureNormalization::fit_per_block(&data).unwrap(),
            FeatureNormalization::fit_per_dimension(&data).unwrap(),
        ] {
            let scale = norm.scale();
            for f in &data {
                let back = norm.denormalize(&norm.normalize(f));
                for d in 0..9 {
                    assert_close!(back[d], f[d], rtol = 1e-13, atol = 1e-13);
                }
                // Derivative of denormalize is the stored scale.
                let g = norm.normalize(f);
                let mut gp = g;
                gp[4] += 1e-3;
                let fd = (norm.denormalize(&gp)[4] - norm.denormalize(&g)[4]) / 1e-3;
                assert_close!(fd, scale[4], rtol = 1e-9, atol = 0.0);
            }
            for f in &data {
                for v in norm.normalize(f) {
                    assert!(v.abs() <= NORMALIZED_BOUND);
                }
            }
        }
    }

    #[test]
    fn bad_training_sets_are_errors() {
        assert!(matches!(
            FeatureNormalization::fit_per_block(&Vec::<Feature>::new()),
            Err(Error::EmptyTrainingSet)
        ));
        let mut data = random_features(3, 5);
        data[2][5] = f64::NAN;
        assert!(matches!(
            FeatureNormalization::fit_per_dimension(&data),
            Err(Error::NonFiniteNormalization { .. })
        ));
        assert!(FeatureNormalization::from_bounds([1.0; 9], [0.0; 9]).is_err());
    }
}
