//! Issue 71's two diagnostics of PB-loss that need no long training (`cargo xtask
//! embed-diagnostics`; docs/EMBEDDING.md, "Gradient norms and the M_phys floor"):
//!
//! - [`gradient_log`]: each stage-1 loss term's gradient norm on the decoder
//!   ([`weft_nn::embed::decoder_gradient_norms`]) at a trained model's stage-1 checkpoints,
//!   with λ_ephys calibrated against the term that dominates;
//! - [`mphys_floor`]: M_phys of the true test frames projected onto a PCA of rank r, split
//!   by force (the inertia and each energy term) and by region (near the grasp or not): the
//!   residual any r-dimensional linear code leaves, whatever it was trained on.

use std::collections::BTreeMap;
use std::path::Path;

use weft_data::ClothDataset;
use weft_nn::embed::{
    EmbedData, EmbedModel, EphysCalibration, FrameRef, GradientNorms, calibrate_ephys, decoder_gradient_norms,
};
use weft_nn::pca::PositionPca;

use super::data::{pca_training_frames, windows};

/// The gradient norms at one set of a model's stage-1 weights.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct CheckpointNorms {
    /// `init` (the seed's starting weights, stage 1's epoch 0), `best` or `last`.
    pub checkpoint: String,
    /// The stage-1 epoch the weights are from.
    pub epoch: usize,
    pub norms: GradientNorms,
    pub calibration: EphysCalibration,
}

/// What `cargo xtask embed-diagnostics gradients` writes.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct GradientLog {
    pub scene: String,
    /// The model's λ_ephys and the scale on `L_phys` (m²/J) it multiplies.
    pub ephys_weight: f64,
    pub phys_scale: f64,
    /// The ratio `λ_ephys ‖∇L_ephys‖ / max_k λ_k ‖∇L_k‖` the calibration asks for.
    pub ratio: f64,
    pub checkpoints: Vec<CheckpointNorms>,
}

/// At most `limit` of `windows`, evenly spaced (all of them without a limit).
fn spread(windows: &[FrameRef], limit: Option<usize>) -> Vec<FrameRef> {
    match limit {
        Some(k) if k < windows.len() => (0..k).map(|i| windows[i * windows.len() / k]).collect(),
        _ => windows.to_vec(),
    }
}

/// The stage-1 gradient norms of the model in `model_dir` (`cargo xtask train embed`) on
/// the dataset in `data_dir` (read with the model's own normalisation), at the seed's
/// starting weights and at stage 1's `best` and `last` checkpoints, over `windows` of the
/// training windows (all without a limit), each with λ_ephys calibrated to `ratio`
/// ([`weft_nn::embed::calibrate_ephys`]).
pub fn gradient_log(
    model_dir: &Path,
    data_dir: &Path,
    windows: Option<usize>,
    ratio: f64,
) -> crate::Result<GradientLog> {
    let dataset = ClothDataset::load(data_dir)?;
    let normalization = weft_nn::checkpoint::read_json(&model_dir.join("normalization.json"))?;
    let data = EmbedData::with_normalization(dataset, normalization)?;
    let model = EmbedModel::load(model_dir, &data, 1)?;
    let state = weft_nn::trainer::TrainingState::read(&weft_nn::embed::stage_dir(model_dir, 1))?;
    let chosen = spread(&data.train_windows, windows);
    let mut checkpoints = Vec::new();
    let fresh = EmbedModel::new(model.config.clone(), &data)?;
    let run = weft_nn::embed::stage_dir(model_dir, 1);
    for (name, epoch) in [("init", 0), ("best", state.best_epoch), ("last", state.epochs_done)] {
        if name != "init" {
            weft_nn::trainer::load_weights(&run.join(name), &fresh.stage_groups(1))?;
        }
        let norms = decoder_gradient_norms(&fresh, &data, &chosen, 1)?;
        let calibration = calibrate_ephys(&norms, ratio)?;
        checkpoints.push(CheckpointNorms {
            checkpoint: name.into(),
            epoch,
            norms,
            calibration,
        });
    }
    Ok(GradientLog {
        scene: data.dataset.name.clone(),
        ephys_weight: model.config.weights.ephys,
        phys_scale: data.phys_scale(model.config.phys_scale),
        ratio,
        checkpoints,
    })
}

/// The region of the mesh within `fraction` of the rest mesh's bounding-box diagonal of a
/// grasped vertex (rest-shape Euclidean distance): where the grasp's prescribed motion
/// bends and stretches the cloth first. Returns the radius (m) and, per vertex, whether it
/// is near.
pub fn near_grasp(data: &EmbedData, fraction: f64) -> crate::Result<(f64, Vec<bool>)> {
    if !(fraction.is_finite() && fraction >= 0.0) {
        return Err(crate::Error::Invalid(format!(
            "the near-grasp fraction must be non-negative and finite, not {fraction}"
        )));
    }
    let rest = data.dataset.rest.positions();
    let (lo, hi) = rest
        .iter()
        .fold((rest[0], rest[0]), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    let radius = fraction * (hi - lo).norm();
    let near = rest
        .iter()
        .map(|p| data.dataset.grasp.iter().any(|&g| (rest[g] - p).norm() <= radius))
        .collect();
    Ok((radius, near))
}

/// Mean over the scored frames of `‖f‖²` over the free DOFs of one region: of the total
/// force `∂L_phys/∂p_m` (M_phys's share from the region) and of each force apart.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RegionResidual {
    pub total: f64,
    /// `inertia`, then each energy term by name ([`weft_sim::ImplicitEuler::l_phys_forces`]).
    pub forces: BTreeMap<String, f64>,
}

/// M_phys of the test frames after a projection.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FloorRow {
    /// The PCA rank asked for; `None`: the true frames, unprojected.
    pub rank: Option<usize>,
    /// Components the PCA kept (fewer than asked when the training frames span less).
    pub components: usize,
    /// M_rms of the projected test frames (mm).
    pub m_rms_mm: f64,
    /// M_phys (N²), as the evaluation scores `pca` (`near.total + far.total`).
    pub m_phys: f64,
    pub near: RegionResidual,
    pub far: RegionResidual,
}

/// What `cargo xtask embed-diagnostics floor` writes.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FloorReport {
    pub scene: String,
    /// The PCA's training frames (at most this many components exist).
    pub training_frames: usize,
    /// Test frames M_phys is scored on (the 3rd to 5th of each test window).
    pub scored_frames: usize,
    /// "Near the grasp": within `near_radius_m` (`near_fraction` of the rest mesh's
    /// bounding-box diagonal) of a grasped vertex, at rest.
    pub near_fraction: f64,
    pub near_radius_m: f64,
    pub near_vertices: usize,
    pub far_vertices: usize,
    pub rows: Vec<FloorRow>,
}

/// M_phys of the test windows with every frame replaced by `project(frame)`, split by
/// force and by the vertices `near` ([`near_grasp`]). The windows and the residual are the
/// evaluation's (`scoring::score`): M_phys from the third frame of each test window on,
/// the projected frames as predecessors, the grasped DOFs prescribed to the frame's controls.
pub fn projected_residual(
    data: &EmbedData,
    near: &[bool],
    project: impl Fn(&[f64]) -> Vec<f64>,
) -> crate::Result<(f64, RegionResidual, RegionResidual)> {
    let frames = &data.test_frames;
    let truth: Vec<&[f64]> = frames
        .iter()
        .map(|f| data.dataset.sequences[f.sequence].frame(f.frame))
        .collect();
    let projected: Vec<Vec<f64>> = truth.iter().map(|x| project(x)).collect();
    let m_rms = weft_nn::metrics::m_rms(&truth.iter().map(|x| x.to_vec()).collect::<Vec<_>>(), &projected)?;
    let fixed = data.integrator.fixed();
    let (mut near_sum, mut far_sum, mut n) = (RegionResidual::default(), RegionResidual::default(), 0usize);
    for w in windows(frames) {
        for i in 2..w.len() {
            let at = frames[w[i]];
            let q = data.dataset.sequences[at.sequence].control(at.frame);
            let p = data.dataset.with_grasp_at(&projected[w[i]], q)?;
            let forces = data
                .integrator
                .l_phys_forces(&projected[w[i - 2]], &projected[w[i - 1]], &p)?;
            // Terms of one name (two spring sets, say) count as one force.
            let mut by_name: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
            let mut total = vec![0.0; p.len()];
            for (name, f) in &forces {
                let acc = by_name.entry(name).or_insert_with(|| vec![0.0; p.len()]);
                for (d, v) in f.iter().enumerate() {
                    acc[d] += v;
                    total[d] += v;
                }
            }
            let add = |region: &mut RegionResidual, inside: bool| {
                let sq = |f: &[f64]| -> f64 {
                    (0..f.len())
                        .filter(|&d| !fixed[d] && near[d / 3] == inside)
                        .map(|d| f[d] * f[d])
                        .sum()
                };
                region.total += sq(&total);
                for (name, f) in &by_name {
                    *region.forces.entry(name.to_string()).or_default() += sq(f);
                }
            };
            add(&mut near_sum, true);
            add(&mut far_sum, false);
            n += 1;
        }
    }
    if n == 0 {
        return Err(crate::Error::Invalid(
            "the dataset has no test window of three frames (sequences of at least 15 frames)".into(),
        ));
    }
    for region in [&mut near_sum, &mut far_sum] {
        region.total /= n as f64;
        region.forces.values_mut().for_each(|v| *v /= n as f64);
    }
    Ok((m_rms, near_sum, far_sum))
}

/// The M_phys floor of the dataset in `data_dir` ([`projected_residual`]): the true frames,
/// then PCAs of each of `ranks` fitted to the frames the embedding trains on
/// (`data::pca_training_frames`, as the evaluation's `pca`), the near-grasp region at
/// `near_fraction` ([`near_grasp`]).
pub fn mphys_floor(data_dir: &Path, ranks: &[usize], near_fraction: f64) -> crate::Result<FloorReport> {
    if ranks.is_empty() || ranks.contains(&0) {
        return Err(crate::Error::Invalid(
            "give at least one PCA rank, each at least 1".into(),
        ));
    }
    let data = EmbedData::new(ClothDataset::load(data_dir)?)?;
    mphys_floor_of(&data, ranks, near_fraction)
}

/// [`mphys_floor`] of a loaded dataset.
pub fn mphys_floor_of(data: &EmbedData, ranks: &[usize], near_fraction: f64) -> crate::Result<FloorReport> {
    let (radius, near) = near_grasp(data, near_fraction)?;
    let training = pca_training_frames(data);
    let full = PositionPca::fit(&training, ranks.iter().copied().max().unwrap_or(0))?;
    let row = |rank: Option<usize>, pca: Option<&PositionPca>| -> crate::Result<FloorRow> {
        let (m_rms_mm, near_r, far_r) = projected_residual(data, &near, |x| match pca {
            Some(pca) => pca.decode(&pca.encode(x)),
            None => x.to_vec(),
        })?;
        Ok(FloorRow {
            rank,
            components: pca.map_or(0, PositionPca::num_components),
            m_rms_mm,
            m_phys: near_r.total + far_r.total,
            near: near_r,
            far: far_r,
        })
    };
    let mut rows = vec![row(None, None)?];
    for &r in ranks {
        rows.push(row(Some(r), Some(&full.truncated(r)))?);
    }
    let near_vertices = near.iter().filter(|n| **n).count();
    Ok(FloorReport {
        scene: data.dataset.name.clone(),
        training_frames: training.len(),
        scored_frames: windows(&data.test_frames)
            .iter()
            .map(|w| w.len().saturating_sub(2))
            .sum(),
        near_fraction,
        near_radius_m: radius,
        near_vertices,
        far_vertices: near.len() - near_vertices,
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluate::embed::tests::simulated_sheet;

    /// The forces after `project`, by region (near, far).
    fn residuals(data: &EmbedData, near: &[bool], project: impl Fn(&[f64]) -> Vec<f64>) -> [RegionResidual; 2] {
        let (_, n, f) = projected_residual(data, near, project).unwrap();
        [n, f]
    }

    /// Frames inside the PCA's span project onto themselves. The sheet's frames are
    /// replaced by `f₀ + (m/19)(f₁₉ − f₀) + cos(m) r`, `r` a fixed 1 cm ripple, a 2-D
    /// affine family: a rank-2 PCA of the training frames leaves M_phys and every force of
    /// it, in both regions, as the frames themselves have them; rank 1 does not.
    #[test]
    fn frames_inside_the_subspace_keep_their_m_phys() {
        let mut dataset = simulated_sheet(20, false);
        let n = 3 * dataset.rest.num_vertices();
        let seq = &mut dataset.sequences[0];
        let (f0, f19) = (seq.frame(0).to_vec(), seq.frame(19).to_vec());
        for (m, frame) in seq.positions.chunks_mut(n).enumerate() {
            let (s, c) = (m as f64 / 19.0, (m as f64).cos());
            for (d, x) in frame.iter_mut().enumerate() {
                *x = f0[d] + s * (f19[d] - f0[d]) + c * 0.01 * (1.7 * d as f64).sin();
            }
        }
        let data = EmbedData::new(dataset).unwrap();
        let report = mphys_floor_of(&data, &[1, 2, 8], 0.2).unwrap();
        assert!(report.near_vertices > 0 && report.far_vertices > 0);
        let [truth, one, two, eight] = [0, 1, 2, 3].map(|k| &report.rows[k]);
        assert_eq!((two.components, eight.components), (2, 2));
        assert!(two.m_rms_mm < 1e-9, "{}", two.m_rms_mm);
        assert!(truth.m_phys > 0.0);
        for (t, p) in [(&truth.near, &two.near), (&truth.far, &two.far)] {
            weft_testkit::assert_close!(p.total, t.total, rtol = 1e-6, atol = 0.0);
            assert_eq!(t.forces.keys().collect::<Vec<_>>(), p.forces.keys().collect::<Vec<_>>());
            for (name, v) in &t.forces {
                weft_testkit::assert_close!(p.forces[name], *v, rtol = 1e-6, atol = 0.0);
            }
        }
        weft_testkit::assert_close!(two.m_phys, truth.m_phys, rtol = 1e-6, atol = 0.0);
        assert_eq!(
            eight,
            &FloorRow {
                rank: Some(8),
                ..two.clone()
            }
        );
        assert!(
            (one.m_phys - truth.m_phys).abs() > 0.1 * truth.m_phys,
            "{one:?} vs {truth:?}"
        );
    }

    /// A rank-0 PCA projects every frame onto the training frames' mean: the predecessors
    /// equal it, so the inertial force vanishes on the free DOFs and M_phys is the
    /// potential's force at the mean with the grasp at the controls, frame by frame. At
    /// radius 0 only the grasped vertices (all prescribed) are near, so their region holds
    /// nothing; at the whole diagonal every vertex is near.
    #[test]
    fn a_rank_0_projection_leaves_the_potential_at_the_mean_frame() {
        let data = EmbedData::new(simulated_sheet(20, false)).unwrap();
        let training = pca_training_frames(&data);
        let mean = PositionPca::fit(&training, 1).unwrap().truncated(0);
        let m: Vec<f64> = mean.decode(&[]);
        let by_hand: Vec<f64> = data.test_frames[2..5]
            .iter()
            .map(|f| {
                let p = data
                    .dataset
                    .with_grasp_at(&m, data.dataset.sequences[0].control(f.frame))
                    .unwrap();
                data.integrator.m_phys(&m, &m, &p).unwrap()
            })
            .collect();
        let by_hand = by_hand.iter().sum::<f64>() / 3.0;
        let (radius, near) = near_grasp(&data, 0.0).unwrap();
        assert_eq!(radius, 0.0);
        assert_eq!(near.iter().filter(|n| **n).count(), data.dataset.grasp.len());
        let [n, f] = residuals(&data, &near, |x| mean.decode(&mean.encode(x)));
        assert_eq!(n.total, 0.0);
        assert_eq!(f.forces["inertia"], 0.0);
        weft_testkit::assert_close!(f.total, by_hand, rtol = 1e-9, atol = 0.0);
        let (_, everywhere) = near_grasp(&data, 1.0).unwrap();
        assert!(everywhere.iter().all(|n| *n));
        let [n, f] = residuals(&data, &everywhere, |x| mean.decode(&mean.encode(x)));
        assert_eq!(f.total, 0.0);
        weft_testkit::assert_close!(n.total, by_hand, rtol = 1e-9, atol = 0.0);
        assert!(near_grasp(&data, -0.1).is_err());
    }

    /// The floor at the latent size is the M_phys the evaluation scores `pca` with, and
    /// the regions sum to it.
    #[test]
    fn the_floor_at_the_latent_size_is_the_evaluations_pca_m_phys() {
        let data = EmbedData::new(simulated_sheet(20, false)).unwrap();
        let report = mphys_floor_of(&data, &[4, 16], 0.2).unwrap();
        assert_eq!(report.rows.len(), 3);
        assert_eq!(report.rows[0].rank, None);
        assert_eq!(report.scored_frames, 3);
        assert_eq!(report.near_vertices + report.far_vertices, data.num_vertices());
        let pca = PositionPca::fit(&pca_training_frames(&data), 16).unwrap();
        let predicted: Vec<Vec<f64>> = data
            .test_frames
            .iter()
            .map(|f| pca.decode(&pca.encode(data.dataset.sequences[f.sequence].frame(f.frame))))
            .collect();
        let scored = super::super::scoring::score(&data, &predicted).unwrap();
        let row = &report.rows[2];
        assert_eq!(row.components, pca.num_components());
        weft_testkit::assert_close!(row.m_phys, scored.m_phys, rtol = 1e-9, atol = 0.0);
        weft_testkit::assert_close!(row.m_rms_mm, scored.m_rms, rtol = 1e-12, atol = 0.0);
        assert!(report.rows[1].m_phys > row.m_phys, "{:?}", report.rows);
        assert!(mphys_floor(Path::new("/nonexistent"), &[0], 0.1).is_err());
    }
}
