//! Experiment `embed`: Tan et al.'s mesh embedding with PB-loss (`ours`), without it
//! (`no-pb`, "[46] + L_vert") and PCA on positions (`pca`), on the design's eight cloth
//! scenes. Each scene's dataset is generated (`cargo xtask dataset`) and both networks
//! trained (`cargo xtask train embed`) into `OUT/embed/`, resuming whatever an earlier run
//! left there. Metrics on the test split (the last 5 of every 17 frames): M_rms, M_STED per
//! 5-frame window, and M_phys on frames whose two predecessors are in their window, with
//! the method's own reconstructions as predecessors (docs/RESULTS.md).

use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

use anyhow::Context;
use clap::{Args as _, FromArgMatches as _};
use weft_nn::data::ClothDataset;
use weft_nn::embed_training::{EmbedData, EmbedModel, EmbedTrainingConfig, FrameRef};
use weft_nn::metrics::{RmsAccumulator, StedParams, ndcg_curve, sted};
use weft_nn::pca::PositionPca;
use weft_nn::rollout::LatentRollout;

use super::EvalContext;
use super::results::{Curve, ExperimentOutput, Timing};
use crate::dataset::Size;
use crate::output::{Array, write_safetensors};
use crate::train::{EmbedArgs, TrainCommand};

/// The design's eight cloth scenes (Tan et al.'s SHEET and BALL datasets): the built-in
/// scenes before the two coarser sheets of the resolution study.
fn scenes() -> &'static [&'static str] {
    &weft_sim::BUILTIN_SCENES[..8]
}

/// Tan et al. Table I: (scene, method, M_rms, M_STED, M_phys) as printed.
const TABLE_I: [(&str, &str, f64, f64, f64); 8] = [
    ("sheet-ms", "ours", 9.724, 0.01556, 14581.46),
    ("sheet-ms", "no-pb", 10.351, 0.01688, 15446.70),
    ("sheet-ms-holes", "ours", 12.456, 0.02443, 19548.58),
    ("sheet-ms-holes", "no-pb", 12.928, 0.02480, 20632.13),
    ("sheet-fem", "ours", 10.671, 0.01398, 29109.03),
    ("sheet-fem", "no-pb", 10.675, 0.01195, 103878.20),
    ("sheet-fem-obstacle", "ours", 8.075, 0.01784, 160545.91),
    ("sheet-fem-obstacle", "no-pb", 8.425, 0.01885, 155117.28),
];

/// The training configuration of each evaluation size.
fn training_config(size: Size) -> EmbedTrainingConfig {
    let mut c = EmbedTrainingConfig::default();
    if size == Size::Quick {
        c.autoencoder.conv_layers = 1;
        c.autoencoder.latent = 16;
        c.latent_hidden = vec![64];
        c.epochs = [20, 20, 5];
        c.adam.learning_rate = 2e-3;
    }
    c
}

fn generate_dataset(scene: &str, size: Size, dir: &Path) -> anyhow::Result<()> {
    if dir.join("manifest.json").exists() {
        return Ok(());
    }
    let cmd = crate::dataset::DatasetArgs::augment_args(clap::Command::new("dataset"));
    let dir_arg = dir.display().to_string();
    let matches =
        cmd.try_get_matches_from(["dataset", scene, "--size", size.as_str(), "--quiet", "--out", &dir_arg])?;
    crate::dataset::run(crate::dataset::DatasetArgs::from_arg_matches(&matches)?)
}

/// Ground-truth solver seconds per frame of a dataset (its `timing.json`).
fn ground_truth_seconds(dir: &Path) -> anyhow::Result<f64> {
    let t: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("timing.json"))?)?;
    let (mut frames, mut seconds) = (0.0, 0.0);
    for v in t["sequences"]
        .as_object()
        .context("timing.json lists no sequences")?
        .values()
    {
        frames += v[0].as_f64().unwrap_or(0.0);
        seconds += v[1].as_f64().unwrap_or(0.0);
    }
    anyhow::ensure!(frames > 0.0, "timing.json counts no frames");
    Ok(seconds / frames)
}

/// The test frames grouped by window (sequence, block of 17).
fn windows(frames: &[FrameRef]) -> Vec<Vec<usize>> {
    let mut out: Vec<Vec<usize>> = Vec::new();
    for (k, f) in frames.iter().enumerate() {
        match out.last_mut() {
            Some(w) if frames[w[0]].sequence == f.sequence && frames[w[0]].frame / 17 == f.frame / 17 => w.push(k),
            _ => out.push(vec![k]),
        }
    }
    out
}

struct Scores {
    m_rms: f64,
    m_sted: f64,
    m_phys: f64,
}

/// Writes `predictions/embed/<scene>/<method>.safetensors`: the reconstructed test frames
/// beside the ground truth, with each frame's sequence and frame index.
fn write_predictions(
    ctx: &EvalContext,
    scene: &str,
    method: &str,
    data: &EmbedData,
    predicted: &[Vec<f64>],
) -> anyhow::Result<()> {
    let dir = ctx.out.join("predictions").join("embed").join(scene);
    std::fs::create_dir_all(&dir)?;
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
    write_safetensors(
        &dir.join(format!("{method}.safetensors")),
        &[
            Array::f64("positions", vec![f, v, 3], &predicted.concat()),
            Array::f64("ground_truth", vec![f, v, 3], &truth),
            Array::i64("frame_index", &index),
        ],
        meta,
    )
}

fn score(data: &EmbedData, predicted: &[Vec<f64>]) -> anyhow::Result<Scores> {
    let frames = &data.test_frames;
    let v = data.num_vertices();
    let map: Vec<usize> = (0..v).collect();
    let truth: Vec<Vec<f64>> = frames
        .iter()
        .map(|f| data.dataset.sequences[f.sequence].frame(f.frame).to_vec())
        .collect();
    let mut acc = RmsAccumulator::default();
    for (p, t) in predicted.iter().zip(&truth) {
        acc.add(p, t, &map);
    }
    let edges = weft_mesh::Topology::new(&data.dataset.rest).edges;
    let params = StedParams {
        speed: 1.0,
        temporal_weight: 1.0,
        dt: data.dataset.scene.dt,
    };
    let (mut sted_sum, mut phys_sum, mut phys_n) = (0.0, 0.0, 0usize);
    let groups = windows(frames);
    for w in &groups {
        let r: Vec<Vec<f64>> = w.iter().map(|&k| truth[k].clone()).collect();
        let p: Vec<Vec<f64>> = w.iter().map(|&k| predicted[k].clone()).collect();
        sted_sum += sted(&edges, &r, &p, params)?.combined;
        for i in 2..w.len() {
            phys_sum += data
                .integrator
                .m_phys(&predicted[w[i - 2]], &predicted[w[i - 1]], &predicted[w[i]])?;
            phys_n += 1;
        }
    }
    Ok(Scores {
        m_rms: acc.m_rms_mm(),
        m_sted: sted_sum / groups.len().max(1) as f64,
        m_phys: phys_sum / phys_n.max(1) as f64,
    })
}

/// nDCG over the full ranking (K = N − 1) of the test frames' codes by their motion
/// labels (Tan et al. §VI-C; docs/RESULTS.md).
fn full_ranking_ndcg(data: &EmbedData, codes: &[Vec<f64>]) -> anyhow::Result<f64> {
    let labels: Vec<u8> = data
        .test_frames
        .iter()
        .map(|f| data.dataset.sequences[f.sequence].labels[f.frame])
        .collect();
    let curve = ndcg_curve(codes, &labels)?;
    Ok(*curve.last().context("fewer than two test frames")?)
}

/// A latent roll-out started from the encoded ground-truth frames `start`.
fn rollout_from<'a>(
    data: &EmbedData,
    model: &'a EmbedModel,
    start: [FrameRef; 2],
) -> anyhow::Result<LatentRollout<'a>> {
    let codes = model.codes(data, &start)?;
    Ok(LatentRollout::new(
        &model.autoencoder,
        &model.simulator,
        data.inverse.clone(),
        data.normalization.clone(),
        &codes[0],
        &codes[1],
    )?)
}

/// Tan et al. Table IV's test: in each 5-frame test window, encode the first two frames,
/// let the latent simulator predict the other three from their controls, decode them
/// (`LatentRollout`), and return M_rms (mm) of the predicted frames.
fn rollout_2_to_3(data: &EmbedData, model: &EmbedModel) -> anyhow::Result<f64> {
    let frames = &data.test_frames;
    let map: Vec<usize> = (0..data.num_vertices()).collect();
    let mut acc = RmsAccumulator::default();
    for w in windows(frames) {
        if w.len() < 5 {
            continue;
        }
        let mut rollout = rollout_from(data, model, [frames[w[0]], frames[w[1]]])?;
        for &k in &w[2..5] {
            let f = frames[k];
            let seq = &data.dataset.sequences[f.sequence];
            let p = rollout.step(seq.control(f.frame))?;
            acc.add(&p, seq.frame(f.frame), &map);
        }
    }
    Ok(acc.m_rms_mm())
}

/// Tan et al. §V-B: a latent roll-out of the whole first sequence from the codes of its
/// frames 0 and 1 and its controls, every frame decoded; the per-frame M_rms against the
/// ground truth shows how the error grows with the number of frames N.
fn long_rollout(scene: &str, method: &str, data: &EmbedData, model: &EmbedModel) -> anyhow::Result<Curve> {
    let seq = &data.dataset.sequences[0];
    let mut rollout = rollout_from(data, model, [0, 1].map(|frame| FrameRef { sequence: 0, frame }))?;
    let map: Vec<usize> = (0..data.num_vertices()).collect();
    let mut curve = Curve {
        scene: scene.into(),
        method: method.into(),
        frames: Vec::new(),
        error_mm: Vec::new(),
    };
    for m in 2..seq.num_frames() {
        let p = rollout.step(seq.control(m))?;
        let mut acc = RmsAccumulator::default();
        curve.frames.push(m as f64);
        curve.error_mm.push(acc.add(&p, seq.frame(m), &map));
    }
    Ok(curve)
}

pub fn run(ctx: &EvalContext) -> anyhow::Result<ExperimentOutput> {
    let mut out = ExperimentOutput::new("embed", ctx.size);
    let root = ctx.out.join("embed");
    let config = training_config(ctx.size);
    std::fs::create_dir_all(&root)?;
    let config_path = root.join("config.json");
    std::fs::write(&config_path, serde_json::to_string_pretty(&config)?)?;
    out.notes.push(format!(
        "embed: {} graph convolution(s), {}-D latent, latent MLP hidden {:?}, epochs per stage {:?}, batch {}, \
         Adam lr {}; λ_ephys = {}, λ_mphys = {} for `ours`, 0 for `no-pb`; PCA with the same latent size; STED \
         with the 1-ring, s = 1 m/s, c = 1",
        config.autoencoder.conv_layers,
        config.autoencoder.latent,
        config.latent_hidden,
        config.epochs,
        config.batch,
        config.adam.learning_rate,
        config.weights.ephys,
        config.weights.mphys
    ));
    for &scene in scenes() {
        let data_dir = root.join("data").join(scene);
        generate_dataset(scene, ctx.size, &data_dir).with_context(|| format!("dataset {scene}"))?;
        let gt = ground_truth_seconds(&data_dir)?;
        let dataset = ClothDataset::load(&data_dir)?;
        let data = EmbedData::new(dataset)?;
        let push = |out: &mut ExperimentOutput, method: &str, s: &Scores, seconds: f64| {
            let timing = Timing {
                seconds_per_frame: Some(seconds),
                ground_truth_seconds_per_frame: Some(gt),
            };
            for (metric, value, unit) in [
                ("m-rms", s.m_rms, "mm"),
                ("m-sted", s.m_sted, "1"),
                ("m-phys", s.m_phys, "N^2"),
            ] {
                out.record(scene, method, metric, value, unit, timing);
                if let Some(r) = out.records.last_mut() {
                    r.split = Some("test".into());
                }
                let paper = TABLE_I
                    .iter()
                    .find(|t| t.0 == scene && t.1 == method)
                    .map(|t| match metric {
                        "m-rms" => t.2,
                        "m-sted" => t.3,
                        _ => t.4,
                    });
                if let Some(p) = paper {
                    out.paper(p);
                }
            }
        };
        let mut ndcg: Vec<(&str, f64)> = Vec::new();
        let mut rollouts: Vec<(&str, f64)> = Vec::new();
        for (method, no_pb) in [("ours", false), ("no-pb", true)] {
            let model_dir = root.join("models").join(scene).join(method);
            crate::train::run(TrainCommand::Embed(EmbedArgs {
                data: data_dir.clone(),
                config: Some(config_path.clone()),
                no_pb,
                stages: vec![1, 2, 3],
                out: model_dir.clone(),
                resume: true,
                quiet: ctx.quiet,
            }))
            .with_context(|| format!("training {method} on {scene}"))?;
            let model = EmbedModel::load(&model_dir, &data)?;
            ndcg.push((
                method,
                full_ranking_ndcg(&data, &model.codes(&data, &data.test_frames)?)?,
            ));
            rollouts.push((method, rollout_2_to_3(&data, &model)?));
            out.curves.push(long_rollout(scene, method, &data, &model)?);
            let t = Instant::now();
            let predicted = model.reconstruct(&data, &data.test_frames, 16)?;
            let seconds = t.elapsed().as_secs_f64() / predicted.len().max(1) as f64;
            push(&mut out, method, &score(&data, &predicted)?, seconds);
            write_predictions(ctx, scene, method, &data, &predicted)?;
        }
        // PCA on the training frames' positions, the autoencoder's latent size.
        let train: Vec<Vec<f64>> = data
            .dataset
            .sequences
            .iter()
            .flat_map(|s| {
                (0..s.num_frames())
                    .filter(|&m| weft_nn::data::is_train_frame(m))
                    .map(|m| s.frame(m).to_vec())
            })
            .collect();
        let pca = PositionPca::fit(&train, config.autoencoder.latent)?;
        let t = Instant::now();
        let predicted: Vec<Vec<f64>> = data
            .test_frames
            .iter()
            .map(|f| pca.decode(&pca.encode(data.dataset.sequences[f.sequence].frame(f.frame))))
            .collect();
        let seconds = t.elapsed().as_secs_f64() / predicted.len().max(1) as f64;
        push(&mut out, "pca", &score(&data, &predicted)?, seconds);
        write_predictions(ctx, scene, "pca", &data, &predicted)?;
        let codes: Vec<Vec<f64>> = data
            .test_frames
            .iter()
            .map(|f| pca.encode(data.dataset.sequences[f.sequence].frame(f.frame)))
            .collect();
        ndcg.push(("pca", full_ranking_ndcg(&data, &codes)?));
        let paper = match scene {
            "sheet-ms" => " (Tan et al. §VI-C: 0.8045)",
            "ball-ms" => " (Tan et al. §VI-C: 0.9128)",
            _ => "",
        };
        out.notes.push(format!(
            "embed/{scene}: {} vertices, {} training windows, {} test frames, PCA kept {} components; nDCG of \
             motion-label retrieval in latent space over the full ranking: {}{paper}; latent roll-out given the \
             first 2 frames of each test window, M_rms of the 3 predicted (Tan Table IV's test): {} mm",
            data.num_vertices(),
            data.train_windows.len(),
            data.test_frames.len(),
            pca.num_components(),
            ndcg.iter()
                .map(|(m, v)| format!("{m} {v:.4}"))
                .collect::<Vec<_>>()
                .join(", "),
            rollouts
                .iter()
                .map(|(m, v)| format!("{m} {v:.3}"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    Ok(out)
}
