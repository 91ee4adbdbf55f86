//! The `linear-filter` row: is the jiggle learnable from the inputs at all (issue 69)?
//!
//! A linear causal filter predicts each vertex's deviation from the skinning row,
//! `d_t = (Y_t − X_t) − (Y₀ − X₀)`, from the skin's own recent motion at that vertex:
//!
//! `d̂_t = Σ_{k<K} W_k v_{t−k}`,  `v_t = X_t − X_{t−1}` (zero before frame 1),
//!
//! one 3 × 3 matrix `W_k` per tap and vertex (world frame), and predicts
//! `Ŷ_t = X_t + (Y₀ − X₀) + d̂_t`. The velocity history over `K` taps spans the skin's
//! accelerations `v_t − v_{t−1}` over `K − 1` of them, so velocity alone is the whole
//! kinematic history a finite filter can use. It reads only the skinned frames `X_0..X_t`
//! (known at runtime) and `Y₀` (the roll-out's start, as every model gets it), never its
//! own output, so its roll-out is its single step and cannot drift. It is fitted by ridge
//! least squares on the training sequences, every frame; `K` and the ridge weight are
//! chosen on the validation split's roll-out error over the scored horizon.

use rayon::prelude::*;
use weft_data::{LimbDataset, LimbSequence};
use weft_linalg::NormalEquations;
use weft_nn::altconv::SequenceErrors;

use super::scoring::vertex_distances;
use crate::evaluate::study::Study;
use crate::paper::Table;
use crate::records::ExperimentOutput;

/// The method's name in the records.
pub(super) const LINEAR_FILTER: &str = "linear-filter";
/// Taps tried: 1 frame (the current skin velocity) to about a second at 30 fps, the
/// fat layer's ringing time on `limb-jiggle` (docs/ALTCONV.md). Taps beyond the shortest
/// training sequence's steps are skipped: no training row would see them.
const TAPS: [usize; 6] = [1, 2, 4, 8, 16, 32];
/// Ridge weights tried, relative to the mean squared feature of the vertex's design (so
/// one grid serves every vertex and both datasets, whose skin speeds differ); the largest
/// shrinks the filter most of the way to the skinning row (zero weights).
const RIDGE: [f64; 6] = [1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0];

/// A fitted filter: `K` taps, one `3K × 3` weight block per vertex (row-major, rows the
/// features `v_t, v_{t−1}, …`, columns the deviation's axes).
#[derive(Debug, Clone)]
pub(super) struct LinearFilter {
    pub taps: usize,
    /// The relative ridge weight it was fitted with.
    pub ridge: f64,
    weights: Vec<Vec<f64>>,
}

/// The skin velocity history of vertex `v` at frame `t`, `[v_t, …, v_{t−K+1}]`, into `out`
/// (`3K` entries; zero where `t − k < 1`: before the first frame nothing is known).
fn features(x: &[Vec<f64>], t: usize, v: usize, taps: usize, out: &mut [f64]) {
    for k in 0..taps {
        for a in 0..3 {
            out[3 * k + a] = if t > k {
                x[t - k][3 * v + a] - x[t - k - 1][3 * v + a]
            } else {
                0.0
            };
        }
    }
}

/// Each vertex's normal equations over every frame `t ≥ 1` of the `train` sequences,
/// with the most taps the grid uses; smaller filters solve their leading blocks.
pub(super) fn normal_equations(train: &[&LimbSequence], taps: usize) -> crate::Result<Vec<NormalEquations>> {
    let vertices = train.first().map_or(0, |s| s.skinned[0].len() / 3);
    let rows: usize = train.iter().map(|s| s.skinned.len() - 1).sum();
    crate::error::ensure!(rows > 0, "the linear filter has no training frame");
    let n = 3 * taps;
    (0..vertices)
        .into_par_iter()
        .map(|v| {
            let mut design = vec![0.0; rows * n];
            let mut targets = vec![0.0; rows * 3];
            let mut r = 0;
            for s in train {
                let (x, y) = (&s.skinned, &s.simulated);
                for t in 1..x.len() {
                    features(x, t, v, taps, &mut design[r * n..(r + 1) * n]);
                    for a in 0..3 {
                        let i = 3 * v + a;
                        targets[3 * r + a] = (y[t][i] - x[t][i]) - (y[0][i] - x[0][i]);
                    }
                    r += 1;
                }
            }
            Ok(NormalEquations::new(&design, &targets, rows, n, 3)?)
        })
        .collect()
}

impl LinearFilter {
    /// The ridge fit with `taps` taps and relative weight `ridge` (λ = ridge × the mean
    /// squared feature; a vertex whose skin never moves gets λ = ridge and zero weights).
    pub fn fit(normals: &[NormalEquations], taps: usize, ridge: f64) -> crate::Result<Self> {
        let weights = normals
            .par_iter()
            .map(|ne| {
                let k = 3 * taps;
                let scale = ne.mean_diagonal(k);
                let lambda = ridge * if scale > 0.0 { scale } else { 1.0 };
                Ok(ne.solve(k, lambda)?)
            })
            .collect::<crate::Result<Vec<_>>>()?;
        Ok(Self { taps, ridge, weights })
    }

    /// The filter's surfaces `Ŷ_1..Ŷ_steps` on `seq`, from its skinned frames and `Y₀`.
    pub fn predict(&self, seq: &LimbSequence, steps: usize) -> Vec<Vec<f64>> {
        let (x, y0) = (&seq.skinned, &seq.simulated[0]);
        let n = 3 * self.taps;
        let mut phi = vec![0.0; n];
        (1..=steps)
            .map(|t| {
                let mut p: Vec<f64> = x[t]
                    .iter()
                    .zip(&x[0])
                    .zip(y0)
                    .map(|((xt, x0), y0)| xt + y0 - x0)
                    .collect();
                for (v, w) in self.weights.iter().enumerate() {
                    features(x, t, v, self.taps, &mut phi);
                    for a in 0..3 {
                        p[3 * v + a] += phi.iter().enumerate().map(|(f, phi)| phi * w[3 * f + a]).sum::<f64>();
                    }
                }
                p
            })
            .collect()
    }

    /// Scores the filter on `seq` as the networks are scored (`score_sequence`): per step
    /// and vertex `‖Ŷ_t − Y_t‖` (m). The single step equals the roll-out: the filter
    /// never reads a previous surface, so teacher forcing changes nothing.
    pub fn score_sequence(&self, seq: &LimbSequence, steps: usize) -> SequenceErrors {
        let t = std::time::Instant::now();
        let rolled = self.predict(seq, steps);
        let rollout_seconds = t.elapsed().as_secs_f64();
        let rollout: Vec<Vec<f64>> = rolled
            .iter()
            .zip(&seq.simulated[1..])
            .map(|(p, y)| vertex_distances(p, y).collect())
            .collect();
        SequenceErrors {
            single: rollout.clone(),
            rollout,
            rollout_surfaces: rolled,
            rollout_seconds,
        }
    }
}

/// The chosen filter and the validation grid behind the choice.
pub(super) struct Selection {
    pub filter: LinearFilter,
    /// `(taps, ridge, validation error in mm)` of every fit tried.
    pub grid: Vec<(usize, f64, f64)>,
    /// The steps the validation error averages over.
    pub steps: usize,
    /// The skinning row's error on the same validation steps (mm).
    pub skinning_mm: f64,
}

/// Fits every `(K, ridge)` of the grid on the training split and keeps the one with the
/// lowest mean vertex error over the validation roll-outs' steps 1..=`horizon` (fewer if
/// a validation sequence is shorter). The test split is not read.
pub(super) fn select(dataset: &LimbDataset, horizon: usize) -> crate::Result<Selection> {
    let train: Vec<&LimbSequence> = dataset.split("train").collect();
    let validation: Vec<&LimbSequence> = dataset.split("validation").collect();
    crate::error::ensure!(
        !train.is_empty() && !validation.is_empty(),
        "the linear filter needs training and validation sequences ({} and {})",
        train.len(),
        validation.len()
    );
    let shortest = |s: &[&LimbSequence]| s.iter().map(|s| s.skinned.len() - 1).min().unwrap_or(0);
    let steps = horizon.min(shortest(&validation));
    let taps: Vec<usize> = TAPS.into_iter().filter(|&k| k <= shortest(&train).max(1)).collect();
    let normals = normal_equations(&train, *taps.last().unwrap_or(&1))?;
    let candidates = taps.iter().flat_map(|&k| RIDGE.map(|r| (k, r)));
    // The study keeps the scores; the chosen filter is refitted (one small solve per
    // vertex) rather than holding every candidate's weights.
    let study = Study::sweep(
        candidates,
        |&(k, ridge)| {
            Ok(mean_error_mm(
                &LinearFilter::fit(&normals, k, ridge)?,
                &validation,
                steps,
            ))
        },
        |&mm| mm,
    )?;
    let &(k, ridge) = study.chosen();
    let filter = LinearFilter::fit(&normals, k, ridge)?;
    let grid = study.trials().iter().map(|&((k, r), mm)| (k, r, mm)).collect();
    // Zero weights are the skinning row: the reference the grid must beat.
    let skinning = LinearFilter {
        taps: 1,
        ridge: f64::INFINITY,
        weights: vec![vec![0.0; 9]; filter.weights.len()],
    };
    let skinning_mm = mean_error_mm(&skinning, &validation, steps);
    Ok(Selection {
        filter,
        grid,
        steps,
        skinning_mm,
    })
}

/// The mean vertex error (mm) of `filter`'s roll-outs over steps 1..=`steps` of `sequences`.
fn mean_error_mm(filter: &LinearFilter, sequences: &[&LimbSequence], steps: usize) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for s in sequences {
        for e in filter.score_sequence(s, steps).rollout {
            sum += e.iter().sum::<f64>();
            count += e.len();
        }
    }
    1e3 * sum / count.max(1) as f64
}

/// Selects the filter on `dataset` ([`select`]) and records the choice: the validation
/// grid as a table (taps × ridge, the chosen cell marked) and a note of what was fitted.
pub(super) fn fit_row(
    out: &mut ExperimentOutput,
    scene: &str,
    dataset: &LimbDataset,
    horizon: usize,
) -> crate::Result<LinearFilter> {
    let sel = select(dataset, horizon)?;
    let mut header = vec!["taps K".to_string()];
    header.extend(RIDGE.iter().map(|r| format!("ridge {r:e}")));
    let rows = sel
        .grid
        .chunks(RIDGE.len())
        .map(|row| {
            let mut cells = vec![row[0].0.to_string()];
            cells.extend(row.iter().map(|&(k, r, mm)| {
                let chosen = k == sel.filter.taps && r == sel.filter.ridge;
                if chosen {
                    format!("**{mm:.3}**")
                } else {
                    format!("{mm:.3}")
                }
            }));
            cells
        })
        .collect();
    out.tables.push(Table {
        title: format!("Linear filter: taps and ridge chosen on validation (`{scene}`)"),
        caption: format!(
            "Mean vertex error (mm) of the validation roll-outs over steps 1–{} of the filter fitted on the training \
             split with K taps of skin velocity history and ridge weight λ = ridge × the vertex's mean squared \
             feature; the lowest (bold) is kept. Skinning scores {:.3} mm on the same steps. The test split plays \
             no part.",
            sel.steps, sel.skinning_mm
        ),
        header,
        rows,
    });
    out.notes.push(format!(
        "altconv/{scene}: `{LINEAR_FILTER}` predicts each vertex's deviation from skinning, (Y_t − X_t) − (Y_0 − X_0), \
         as Σ_k W_k (X_{{t−k}} − X_{{t−k−1}}) with a 3×3 W_k per tap and vertex (world frame), ridge least squares on every \
         frame of the training sequences; chosen on validation: K = {} taps, ridge {:e}. It reads only skinned frames \
         and Y_0, never its own output: its single step is its roll-out, it has no seeds",
        sel.filter.taps, sel.filter.ridge
    ));
    Ok(sel.filter)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-vertex sequence whose skin moves by `velocity(t)` per frame and whose tissue
    /// deviates from the skinned surface by `deviation(t, x)` (x the skin's velocities).
    fn sequence(
        frames: usize,
        velocity: impl Fn(usize) -> [f64; 3],
        deviation: impl Fn(usize, &[[f64; 3]]) -> [f64; 3],
    ) -> LimbSequence {
        let v: Vec<[f64; 3]> = (0..frames)
            .map(|t| if t == 0 { [0.0; 3] } else { velocity(t) })
            .collect();
        let mut x = vec![vec![0.1, 0.2, 0.3]];
        for t in 1..frames {
            let p: Vec<f64> = (0..3).map(|a| x[t - 1][a] + v[t][a]).collect();
            x.push(p);
        }
        let offset = [0.01, -0.02, 0.005];
        let y = (0..frames)
            .map(|t| {
                let d = deviation(t, &v);
                (0..3).map(|a| x[t][a] + offset[a] + d[a]).collect()
            })
            .collect();
        LimbSequence {
            index: 0,
            split: "train".into(),
            skinned: x,
            simulated: y,
        }
    }

    fn wiggle(t: usize) -> [f64; 3] {
        let t = t as f64;
        [(0.7 * t).sin(), (1.3 * t + 0.4).cos(), 0.3 * (2.1 * t).sin() + 0.1]
    }

    #[test]
    fn a_deviation_linear_in_the_velocity_history_is_recovered() {
        // d_t = A v_t + B v_{t−1}, with B mixing the axes (so a per-axis fit would fail).
        let a = [[0.5, 0.0, 0.1], [0.0, -0.2, 0.0], [0.3, 0.0, 0.05]];
        let b = [[0.0, 0.4, 0.0], [-0.1, 0.0, 0.2], [0.0, 0.0, -0.3]];
        let dev = |t: usize, v: &[[f64; 3]]| {
            let prev = if t >= 2 { v[t - 1] } else { [0.0; 3] };
            let cur = if t >= 1 { v[t] } else { [0.0; 3] };
            std::array::from_fn(|i| (0..3).map(|j| a[i][j] * cur[j] + b[i][j] * prev[j]).sum())
        };
        let seq = sequence(30, wiggle, dev);
        let normals = normal_equations(&[&seq], 4).unwrap();
        let f = LinearFilter::fit(&normals, 2, 1e-12).unwrap();
        // Weights: row f = feature (v_t axes, then v_{t−1} axes), column = output axis.
        for j in 0..3 {
            for i in 0..3 {
                assert!((f.weights[0][3 * j + i] - a[i][j]).abs() < 1e-6, "A[{i}][{j}]");
                assert!((f.weights[0][3 * (3 + j) + i] - b[i][j]).abs() < 1e-6, "B[{i}][{j}]");
            }
        }
        // Its roll-out is then the truth; one tap cannot be (B ≠ 0).
        let e = f.score_sequence(&seq, 29);
        assert!(e.rollout.iter().flatten().all(|&e| e < 1e-6));
        assert_eq!(e.single, e.rollout);
        let one = LinearFilter::fit(&normals, 1, 1e-12).unwrap();
        assert!(one.score_sequence(&seq, 29).rollout.iter().flatten().any(|&e| e > 1e-3));
    }

    #[test]
    fn a_one_tap_fit_is_the_hand_computed_ratio() {
        // Skin velocity (1, 0, 0) then (2, 0, 0), (0, 0, 0); deviations along x of 3, 5, 1.
        // One tap on v_t: w_xx = Σ v d / (Σ v² + λ) = (3 + 10) / (1 + 4 + λ); the other
        // axes never move, so their weights are 0, and λ = ρ × (mean v²) = ρ × 5/3.
        let v = [[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0; 3]];
        let d = [0.0, 3.0, 5.0, 1.0];
        let seq = sequence(4, |t| v[t], |t, _| [d[t], 0.0, 0.0]);
        let normals = normal_equations(&[&seq], 1).unwrap();
        let ridge = 0.3;
        let f = LinearFilter::fit(&normals, 1, ridge).unwrap();
        let lambda = ridge * 5.0 / 3.0;
        assert!(
            (f.weights[0][0] - 13.0 / (5.0 + lambda)).abs() < 1e-12,
            "{:?}",
            f.weights[0]
        );
        assert!(f.weights[0][1..].iter().all(|w| w.abs() < 1e-12));
        // Its prediction at frame 2: X_2 + (Y₀ − X₀) + w · 2 along x.
        let p = f.predict(&seq, 2);
        let expected = seq.skinned[2][0] + 0.01 + 2.0 * f.weights[0][0];
        assert!((p[1][0] - expected).abs() < 1e-12);
    }

    #[test]
    fn a_filter_never_reads_the_future_nor_the_truth_past_frame_zero() {
        // Changing the truth after frame 0, or the skin after frame t, leaves Ŷ_1..Ŷ_t.
        let dev = |t: usize, v: &[[f64; 3]]| [0.2 * v[t][0], 0.0, 0.0];
        let seq = sequence(12, wiggle, dev);
        let f = LinearFilter::fit(&normal_equations(&[&seq], 4).unwrap(), 4, 1e-3).unwrap();
        let mut other = seq.clone();
        for t in 1..12 {
            other.simulated[t][1] += 1.0;
        }
        for t in 7..12 {
            other.skinned[t][2] -= 0.5;
        }
        assert_eq!(f.predict(&seq, 6), f.predict(&other, 6));
        assert_ne!(f.predict(&seq, 7), f.predict(&other, 7));
    }
}
