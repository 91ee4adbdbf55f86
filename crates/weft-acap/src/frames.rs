//! ACAP over a sequence of frames, as `cargo xtask acap` runs it: encoding many frames
//! (serially, each seeded from the previous, or in parallel chunks) and measuring the
//! ACAP⁻¹(ACAP(p)) round trip of each frame with only the pins fixed. Files are the
//! caller's (weft-data's `arrays`); this is the arithmetic over frames.

use nalgebra::Vector3;
use serde::Serialize;

use crate::{AcapFeatures, Error, Feature, PoissonPseudoInverse, ReconstructionError, Result};

/// Frames encoded in parallel at a time (progress is reported per chunk).
const CHUNK: usize = 64;

/// Encodes `frames`. With `sequence`, serially, each frame's log-rotations seeded from the
/// previous frame's so they do not jump when a rotation passes π; otherwise in parallel.
/// `progress(n)` is called after every `n` frames encoded.
pub fn encode_frames(
    acap: &AcapFeatures,
    frames: &[Vec<Vector3<f64>>],
    sequence: bool,
    mut progress: impl FnMut(u64),
) -> Result<Vec<Vec<Feature>>> {
    let mut features: Vec<Vec<Feature>> = Vec::with_capacity(frames.len());
    if sequence {
        for (k, p) in frames.iter().enumerate() {
            let (f, _) = acap
                .encode_with_report(p, features.last().map(Vec::as_slice))
                .map_err(|e| e.at_frame(k))?;
            features.push(f);
            progress(1);
        }
    } else {
        for (c, chunk) in frames.chunks(CHUNK).enumerate() {
            features.extend(acap.encode_batch(chunk).map_err(|e| e.at_frame(CHUNK * c))?);
            progress(chunk.len() as u64);
        }
    }
    Ok(features)
}

/// The round trip's error per frame and over all frames, in fractions of each frame's
/// bounding-box diagonal.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RoundTripReport {
    pub worst_max_error: f64,
    pub worst_rms_error: f64,
    pub mean_rms_error: f64,
    /// (max, RMS) per frame.
    pub per_frame_max_rms: Vec<(f64, f64)>,
}

/// Encodes every frame, decodes it with only `pins` fixed where the frame has them, and
/// measures the vertex error; `progress()` after each frame.
pub fn round_trip(
    acap: &AcapFeatures,
    frames: &[Vec<Vector3<f64>>],
    pins: &[usize],
    mut progress: impl FnMut(),
) -> Result<RoundTripReport> {
    let inverse = PoissonPseudoInverse::new(acap, pins)?;
    let mut per_frame = Vec::with_capacity(frames.len());
    for p in frames {
        let f = acap.encode(p)?;
        let pin_positions: Vec<_> = pins.iter().map(|&i| p[i]).collect();
        let back = inverse.decode(&f, &pin_positions)?;
        let e = ReconstructionError::between(p, &back)?;
        per_frame.push((e.max_relative(), e.rms_relative()));
        progress();
    }
    Ok(RoundTripReport {
        worst_max_error: per_frame.iter().map(|e| e.0).fold(0.0, f64::max),
        worst_rms_error: per_frame.iter().map(|e| e.1).fold(0.0, f64::max),
        mean_rms_error: per_frame.iter().map(|e| e.1).sum::<f64>() / per_frame.len().max(1) as f64,
        per_frame_max_rms: per_frame,
    })
}

impl Error {
    /// This error, said to have happened encoding frame `frame` (or the chunk from it).
    pub fn at_frame(self, frame: usize) -> Self {
        Error::AtFrame {
            frame,
            source: Box::new(self),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::AcapSettings;

    #[test]
    fn frames_encode_alike_in_sequence_and_in_parallel_and_round_trip() {
        let rest = weft_mesh::generators::sheet(5, 1.0).unwrap();
        let acap = AcapFeatures::new(&rest, AcapSettings::default()).unwrap();
        let bent = |k: f64| -> Vec<Vector3<f64>> {
            rest.positions()
                .iter()
                .map(|p| Vector3::new(p.x, p.y, 0.1 * k * p.x * p.x))
                .collect()
        };
        let frames: Vec<_> = (0..3).map(|k| bent(k as f64)).collect();
        let mut seen = 0;
        let serial = encode_frames(&acap, &frames, true, |n| seen += n).unwrap();
        let parallel = encode_frames(&acap, &frames, false, |_| {}).unwrap();
        assert_eq!(seen, 3);
        for (a, b) in serial.iter().flatten().zip(parallel.iter().flatten()) {
            assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9));
        }
        let report = round_trip(&acap, &frames, &[0, 4], || {}).unwrap();
        assert_eq!(report.per_frame_max_rms.len(), 3);
        // The rest frame comes back exactly; bent ones within the pseudo-inverse's error.
        assert!(report.per_frame_max_rms[0].0 < 1e-9, "{report:?}");
        assert!(report.worst_max_error < 0.05 && report.worst_rms_error <= report.worst_max_error);
    }
}
