//! The `drape` and `drape-loose` datasets (design §8, Geng et al. §2): poses `θ` of the
//! limb with the sleeve's kinematic guess `r̃(θ)` and its draped ground truth `r(θ)`
//! (`weft_sim::scenes::drape`) — the close-fitting sleeve ([`DrapeParams::standard`])
//! and the loose one ([`DrapeParams::loose`]).
//!
//! Examples are stored in chunks (one "sequence" of the dataset machinery per chunk, so
//! sharding, resuming and checksums work unchanged); the chunks are split in order into
//! training, validation and test. Example `j` of chunk `i` draws its pose from its own
//! stream, seeded by `(sequence seed of i, j)`, so the examples of a chunk are solved in
//! parallel and any chunk reproduces alone. A pose whose Newton solve does not converge
//! is replaced by the next draw of the same stream (at most [`MAX_DRAWS`] draws); the
//! replaced poses are recorded in the chunk's metadata.

use std::collections::HashMap;

use crate::error::Context;
use indicatif::ProgressBar;
use rayon::prelude::*;
use weft_sim::rng::SplitMix64;
use weft_sim::scenes::drape::{Drape, DrapeExample, DrapeParams, POSE_ANGLES};
use weft_sim::scenes::soft_tissue::ArmPose;

use crate::files::Array;
use crate::spec::{DatasetSpec, Size, StoredSequence};

/// The close-fitting sleeve's dataset.
pub const NAME: &str = crate::spec::DRAPE;
/// The loose sleeve's dataset.
pub const LOOSE: &str = crate::spec::DRAPE_LOOSE;

/// Draws of a pose before an example slot gives up.
pub const MAX_DRAWS: usize = 8;

pub use crate::spec::drape_counts as counts;

/// The scene's parameters of drape dataset `name` (`drape` or `drape-loose`) at a size.
pub fn params(name: &str, size: Size) -> DrapeParams {
    match (name == LOOSE, size) {
        (false, Size::Quick) => DrapeParams::quick(),
        (false, Size::Standard | Size::Paper) => DrapeParams::standard(),
        (true, Size::Quick) => DrapeParams::loose_quick(),
        (true, Size::Standard | Size::Paper) => DrapeParams::loose(),
    }
}

/// Solves example `j` of the chunk with sequence seed `seed`; returns it and the poses
/// that were replaced, each with its solver's error.
pub fn example(drape: &Drape, seed: u64, j: usize) -> crate::Result<(DrapeExample, Vec<(ArmPose, String)>)> {
    let mut rng = SplitMix64::new(crate::spec::sequence_seed(seed, j));
    let mut rejected = Vec::new();
    for _ in 0..MAX_DRAWS {
        let pose = drape.sample_pose(&mut rng);
        match drape.solve(&pose) {
            Ok(e) => return Ok((e, rejected)),
            Err(e) => rejected.push((pose, e.to_string())),
        }
    }
    Err(crate::Error::Incomplete(format!(
        "{MAX_DRAWS} poses in a row did not converge; the last: {}",
        rejected.last().map_or("", |r| r.1.as_str())
    )))
}

/// Generates chunk `i` (sequence seed `seed`).
pub fn chunk(spec: &DatasetSpec, seed: u64, i: usize, bar: &ProgressBar) -> crate::Result<StoredSequence> {
    let drape = Drape::new(params(&spec.name, spec.size))?;
    let start = std::time::Instant::now();
    let solved: Vec<(DrapeExample, Vec<(ArmPose, String)>)> = (0..spec.frames)
        .into_par_iter()
        .map(|j| {
            let r = example(&drape, seed, j).with_context(|| format!("drape chunk {i}, example {j}"));
            bar.inc(1);
            r
        })
        .collect::<crate::Result<_>>()?;
    let seconds = start.elapsed().as_secs_f64();
    let (f, v) = (solved.len(), drape.sleeve().num_vertices());
    let poses: Vec<f64> = solved.iter().flat_map(|(e, _)| e.pose.angles()).collect();
    let guess: Vec<f64> = solved.iter().flat_map(|(e, _)| e.guess.iter().copied()).collect();
    let truth: Vec<f64> = solved.iter().flat_map(|(e, _)| e.truth.iter().copied()).collect();
    let iterations: Vec<usize> = solved.iter().map(|(e, _)| e.report.iterations).collect();
    let rejected: Vec<serde_json::Value> = solved
        .iter()
        .enumerate()
        .flat_map(|(j, (_, r))| {
            r.iter()
                .map(move |(p, e)| serde_json::json!({"example": j, "pose": p.angles(), "error": e}))
        })
        .collect();
    let mut metadata = HashMap::new();
    metadata.insert("newton_iterations".into(), serde_json::to_string(&iterations)?);
    metadata.insert("rejected_poses".into(), serde_json::to_string(&rejected)?);
    if drape.params().settle_steps > 0 {
        let settle: Vec<usize> = solved.iter().map(|(e, _)| e.settle_iterations).collect();
        metadata.insert("settle_iterations".into(), serde_json::to_string(&settle)?);
    }
    metadata.insert(
        "units".into(),
        "pose [examples, 4]: shoulder flexion, shoulder abduction, shoulder twist, elbow flexion (rad); guess \
         and truth \
         [examples, vertices, 3]: the sleeve's kinematic guess and its draped equilibrium (m), vertices as in \
         sleeve.obj"
            .into(),
    );
    Ok(StoredSequence {
        arrays: vec![
            Array::f64("pose", vec![f, POSE_ANGLES], &poses),
            Array::f64("guess", vec![f, v, 3], &guess),
            Array::f64("truth", vec![f, v, 3], &truth),
        ],
        metadata,
        frames: f,
        simulated_frames: f,
        solver_seconds: seconds,
        error: None,
    })
}
