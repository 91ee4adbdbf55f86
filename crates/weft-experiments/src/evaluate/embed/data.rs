//! The embed experiment's data: each scene's dataset generated and loaded, the frame sets
//! the metrics read (test windows, validation windows, the frames PCA fits) and the test
//! predictions written beside the ground truth. Not the dataset format (weft-data) nor the
//! networks' features (`weft_nn::embed::EmbedData`).

use std::collections::HashMap;
use std::path::Path;

use weft_data::ClothDataset;
use weft_data::files::{Array, write_safetensors};
use weft_nn::embed::{EmbedData, FrameRef};

use crate::error::Context;
use crate::evaluate::context::EvalContext;
use crate::records::ExperimentOutput;

/// The validation windows' frames, each window's two predecessors before it.
pub(super) fn validation_frames(data: &EmbedData) -> crate::Result<Vec<FrameRef>> {
    let windows = &data.validation_windows;
    crate::error::ensure!(!windows.is_empty(), "the dataset has no validation window");
    Ok(windows
        .iter()
        .flat_map(|w| {
            (0..3).rev().map(move |back| FrameRef {
                sequence: w.sequence,
                frame: w.frame - back,
            })
        })
        .collect())
}

/// The test frames grouped by window (sequence, block of 17).
pub(super) fn windows(frames: &[FrameRef]) -> Vec<Vec<usize>> {
    let mut out: Vec<Vec<usize>> = Vec::new();
    for (k, f) in frames.iter().enumerate() {
        match out.last_mut() {
            Some(w) if frames[w[0]].sequence == f.sequence && frames[w[0]].frame / 17 == f.frame / 17 => w.push(k),
            _ => out.push(vec![k]),
        }
    }
    out
}

/// Writes `path` (`predictions/embed/<scene>/<method>.safetensors` in the report): the
/// reconstructed test frames beside the ground truth, with each frame's sequence and frame
/// index.
pub(super) fn write_predictions(path: &Path, data: &EmbedData, predicted: &[Vec<f64>]) -> crate::Result<()> {
    let (f, v) = (predicted.len(), data.num_vertices());
    let truth: Vec<f64> = data
        .test_frames
        .iter()
        .flat_map(|fr| data.dataset.sequences[fr.sequence].frame(fr.frame).iter().copied())
        .collect();
    let index: Vec<i64> = data
        .test_frames
        .iter()
        .flat_map(|fr| [fr.sequence as i64, fr.frame as i64])
        .collect();
    let mut meta = HashMap::new();
    meta.insert(
        "units".into(),
        "positions and ground_truth [frames, vertices, 3] in metres, the test frames of the dataset; frame_index \
         [frames * 2]: (sequence, frame) of each"
            .into(),
    );
    Ok(write_safetensors(
        path,
        &[
            Array::f64("positions", vec![f, v, 3], &predicted.concat()),
            Array::f64("ground_truth", vec![f, v, 3], &truth),
            Array::i64("frame_index", &index),
        ],
        meta,
    )?)
}

/// Generates (or resumes) `scene`'s dataset in `OUT/embed/data/<scene>`, loads it for the
/// networks and returns it with the simulator's seconds per frame; the sequences the
/// simulator stopped are added to `out`'s failures.
pub(super) fn scene_data(
    ctx: &EvalContext,
    scene: &str,
    out: &mut ExperimentOutput,
) -> crate::Result<(EmbedData, f64)> {
    let data_dir = ctx.out.join("embed").join("data").join(scene);
    let stopped = crate::evaluate::context::generate_dataset(ctx, scene, &data_dir)
        .with_context(|| format!("dataset {scene}"))?;
    out.failures.extend(stopped);
    let gt = crate::evaluate::context::ground_truth_seconds(&data_dir)?;
    let dataset = ClothDataset::load(&data_dir)?;
    Ok((EmbedData::new(dataset)?, gt))
}

/// The frames the embedding trains on (Tan's training frames less the validation ones),
/// every sequence's in order: what PCA is fitted to.
pub(super) fn pca_training_frames(data: &EmbedData) -> Vec<Vec<f64>> {
    data.dataset
        .sequences
        .iter()
        .flat_map(|s| {
            (0..s.num_frames())
                .filter(|&m| weft_data::is_train_frame(m) && !weft_data::is_validation_frame(m))
                .map(|m| s.frame(m).to_vec())
        })
        .collect()
}
