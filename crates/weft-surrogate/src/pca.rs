//! PCA on vertex positions: Tan et al.'s linear baseline with the same latent size as
//! the autoencoder.
//!
//! With F training frames of 3V coordinates (F ≪ 3V), the principal directions come from
//! the F × F Gram matrix of the centred frames: if `G u = λ u`, then `Xᵀu / √λ` is a unit
//! principal direction with variance `λ`. This costs O(F² · 3V) instead of an SVD of the
//! F × 3V matrix.

use std::collections::BTreeMap;

use nalgebra::{DMatrix, SymmetricEigen};

use crate::error::{Error, Result};

/// A fitted PCA: the mean frame and orthonormal principal directions.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct PositionPca {
    mean: Vec<f64>,
    /// One unit direction (3V values) per component, by decreasing variance.
    components: Vec<Vec<f64>>,
    /// The variance along each direction (m²), summed over frames.
    variances: Vec<f64>,
}

impl PositionPca {
    /// Fits up to `k` components on `frames`; directions with a variance below round-off
    /// (1e-12 of the largest) are dropped, so fewer come back when the data span less.
    pub fn fit(frames: &[Vec<f64>], k: usize) -> Result<Self> {
        let f = frames.len();
        let n = frames.first().map_or(0, Vec::len);
        if f == 0 || n == 0 || frames.iter().any(|x| x.len() != n) {
            return Err(Error::Shape {
                what: "PCA frames",
                expected: "at least one frame, all of one length".into(),
                got: format!("{f} frames"),
            });
        }
        if let Some(i) = frames.iter().flatten().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "PCA frames",
                index: i,
            });
        }
        let mean: Vec<f64> = (0..n)
            .map(|j| frames.iter().map(|x| x[j]).sum::<f64>() / f as f64)
            .collect();
        let centred: Vec<Vec<f64>> = frames
            .iter()
            .map(|x| x.iter().zip(&mean).map(|(a, m)| a - m).collect())
            .collect();
        let gram = DMatrix::<f64>::from_fn(f, f, |i, j| {
            centred[i].iter().zip(&centred[j]).map(|(a, b)| a * b).sum::<f64>()
        });
        let eig = SymmetricEigen::new(gram);
        let mut order: Vec<usize> = (0..f).collect();
        let values: Vec<f64> = eig.eigenvalues.iter().copied().collect();
        order.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
        let largest = values[order[0]].max(0.0);
        let mut components = Vec::new();
        let mut variances = Vec::new();
        for &i in order.iter().take(k) {
            let lambda = values[i];
            if !(lambda > 1e-12 * largest) {
                break;
            }
            let u = eig.eigenvectors.column(i);
            let s = lambda.sqrt();
            let dir: Vec<f64> = (0..n)
                .map(|j| (0..f).map(|r| centred[r][j] * u[r]).sum::<f64>() / s)
                .collect();
            components.push(dir);
            variances.push(lambda);
        }
        Ok(Self {
            mean,
            components,
            variances,
        })
    }

    /// The length of a frame (3V).
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// The fit as f64 arrays named `<name>.mean` `[3V]`, `<name>.components` `[k, 3V]`
    /// and `<name>.variances` `[k]`, for a model directory's safetensors file.
    pub fn to_arrays(&self, name: &str) -> Vec<weft_data::files::Array> {
        use weft_data::files::Array;
        let (k, n) = (self.components.len(), self.mean.len());
        vec![
            Array::f64(&format!("{name}.mean"), vec![n], &self.mean),
            Array::f64(&format!("{name}.components"), vec![k, n], &self.components.concat()),
            Array::f64(&format!("{name}.variances"), vec![k], &self.variances),
        ]
    }

    /// The fit [`PositionPca::to_arrays`] wrote under `name`; `path` names the file in
    /// errors.
    pub fn from_arrays(arrays: &BTreeMap<String, Vec<f64>>, name: &str, path: &str) -> Result<Self> {
        let get = |part: &str| -> Result<Vec<f64>> {
            arrays
                .get(&format!("{name}.{part}"))
                .cloned()
                .ok_or_else(|| Error::Checkpoint {
                    path: path.into(),
                    reason: format!("no array {name}.{part}"),
                })
        };
        let (mean, flat, variances) = (get("mean")?, get("components")?, get("variances")?);
        let n = mean.len();
        if n == 0 || flat.len() != variances.len() * n {
            return Err(Error::Checkpoint {
                path: path.into(),
                reason: format!(
                    "{name}: {} component values for {} components of {n}",
                    flat.len(),
                    variances.len()
                ),
            });
        }
        Ok(Self {
            mean,
            components: flat.chunks_exact(n).map(<[f64]>::to_vec).collect(),
            variances,
        })
    }

    pub fn num_components(&self) -> usize {
        self.components.len()
    }

    pub fn variances(&self) -> &[f64] {
        &self.variances
    }

    /// The PCA of the leading `k` components (all of them when `k` is larger): what
    /// [`PositionPca::fit`] with `k` returns on the same frames, without a second fit.
    pub fn truncated(&self, k: usize) -> Self {
        let k = k.min(self.components.len());
        Self {
            mean: self.mean.clone(),
            components: self.components[..k].to_vec(),
            variances: self.variances[..k].to_vec(),
        }
    }

    /// The code of frame `x`: its coordinates along the directions.
    pub fn encode(&self, x: &[f64]) -> Vec<f64> {
        self.components
            .iter()
            .map(|c| c.iter().zip(x).zip(&self.mean).map(|((d, a), m)| d * (a - m)).sum())
            .collect()
    }

    /// The frame of code `z`.
    pub fn decode(&self, z: &[f64]) -> Vec<f64> {
        let mut x = self.mean.clone();
        for (c, &w) in self.components.iter().zip(z) {
            x.iter_mut().zip(c).for_each(|(a, d)| *a += w * d);
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reconstruction_error_is_the_discarded_variance() {
        // Frames = mean + 3·a·e0 + 1·b·e1 + 0.1·c·e2 with orthonormal e's and zero-mean
        // coefficient sequences: keeping two components leaves exactly the third's energy.
        let n = 12;
        let e: Vec<Vec<f64>> = (0..3)
            .map(|k| (0..n).map(|j| if j % 3 == k { 0.5 } else { 0.0 }).collect())
            .collect();
        let coeffs = [[1.0, -1.0, 1.0], [-1.0, 1.0, 1.0], [1.0, 1.0, -1.0], [-1.0, -1.0, -1.0]];
        let frames: Vec<Vec<f64>> = coeffs
            .iter()
            .map(|c| {
                (0..n)
                    .map(|j| 2.0 + 3.0 * c[0] * e[0][j] + c[1] * e[1][j] + 0.1 * c[2] * e[2][j])
                    .collect()
            })
            .collect();
        let pca = PositionPca::fit(&frames, 2).unwrap();
        assert_eq!(pca.num_components(), 2);
        assert!((pca.variances()[0] - 4.0 * 9.0).abs() < 1e-9 && (pca.variances()[1] - 4.0).abs() < 1e-9);
        let residual: f64 = frames
            .iter()
            .map(|x| {
                pca.decode(&pca.encode(x))
                    .iter()
                    .zip(x)
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f64>()
            })
            .sum();
        assert!((residual - 4.0 * 0.01).abs() < 1e-12, "{residual}");
        // All three components reproduce the frames; a fourth does not exist.
        let full = PositionPca::fit(&frames, 10).unwrap();
        assert_eq!(full.num_components(), 3);
        for x in &frames {
            let y = full.decode(&full.encode(x));
            assert!(y.iter().zip(x).all(|(a, b)| (a - b).abs() < 1e-12));
        }
        assert!(PositionPca::fit(&[], 2).is_err());
        // Truncating the full fit is the fit of fewer components.
        let two = full.truncated(2);
        assert_eq!(two.num_components(), 2);
        assert_eq!(two.variances(), pca.variances());
        for x in &frames {
            assert_eq!(two.decode(&two.encode(x)), pca.decode(&pca.encode(x)));
        }
        assert_eq!(full.truncated(99).num_components(), 3);
    }
}
