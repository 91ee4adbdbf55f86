//! NNWarp's runtime run frame by frame against the full nonlinear FEM it stands in for
//! (NNWarp §6): the one loop behind `cargo xtask warp --reference` and the evaluation's
//! trajectory figure (NNWarp Fig. 15).
//!
//! Each frame steps the runtime ([`NnWarpSimulation`]: the pre-factorised linear solve,
//! then the node-wise correction), the reference (the scene as written, a
//! [`VolumeSimulation`]) and any further simulations of the same body stepped beside it
//! (linear FEM run as a scene of its own, say), and measures every displacement against
//! the reference's with [`rel_error`]. The caller sees each frame's displacements as they
//! come (to write them or follow a node) and gets the per-frame errors and timings back.
//!
//! What is not here: building the scenes or the runtime (the caller's: a command line
//! loads a scene file, the evaluation sets up its own beam), and writing anything.

use std::time::Instant;

use weft_sim::VolumeSimulation;

use crate::error::Error;
use crate::nnwarp::{NnWarpFrame, NnWarpSimulation, rel_error};

/// The simulations stepped beside NNWarp's runtime.
#[derive(Debug)]
pub struct ReferenceTwins<'a> {
    /// The scene as written (full nonlinear FEM): every error is measured against it.
    pub reference: &'a mut VolumeSimulation,
    /// Further simulations of the same body, each compared with the reference (e.g. the
    /// scene with a linear material, as its own implicit-Euler run).
    pub others: Vec<&'a mut VolumeSimulation>,
}

/// One frame as the loop hands it to the caller.
#[derive(Debug)]
pub struct FrameView<'a> {
    /// 1 for the first frame stepped.
    pub frame: usize,
    /// The runtime's frame: NNWarp's displacements, the linear solve's, and their timings.
    pub runtime: &'a NnWarpFrame,
    /// The reference's displacements (m, flat), when there is one.
    pub reference: Option<&'a [f64]>,
    /// The displacements of [`ReferenceTwins::others`], in their order.
    pub others: &'a [Vec<f64>],
}

/// One frame's errors against the reference and its timings.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameErrors {
    /// 1 for the first frame stepped.
    pub frame: usize,
    /// The runtime's load rotation and pre-factorised solve (s).
    pub solve_seconds: f64,
    /// The runtime's node-wise correction (s).
    pub warp_seconds: f64,
    /// The reference's step (s), when there is one.
    pub reference_seconds: Option<f64>,
    /// [`rel_error`] of NNWarp's displacements against the reference's.
    pub nnwarp: Option<f64>,
    /// [`rel_error`] of the runtime's uncorrected linear solve against the reference's.
    pub linear_solve: Option<f64>,
    /// [`rel_error`] of each of [`ReferenceTwins::others`] against the reference's (empty
    /// without a reference).
    pub others: Vec<f64>,
}

/// Every frame of a run against the reference.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReferenceReport {
    pub frames: Vec<FrameErrors>,
}

impl ReferenceReport {
    /// The runtime's solve time over every frame (s).
    pub fn solve_seconds(&self) -> f64 {
        self.frames.iter().fold(0.0, |a, f| a + f.solve_seconds)
    }

    /// The runtime's correction time over every frame (s).
    pub fn warp_seconds(&self) -> f64 {
        self.frames.iter().fold(0.0, |a, f| a + f.warp_seconds)
    }

    /// The reference's time over every frame (s), when there is one.
    pub fn reference_seconds(&self) -> Option<f64> {
        self.frames
            .iter()
            .map(|f| f.reference_seconds)
            .try_fold(0.0, |a, s| Some(a + s?))
    }
}

/// Steps `runtime` and, with `twins`, the reference and the others beside it for `frames`
/// frames; `on_frame` sees each frame's displacements. Returns every frame's errors against
/// the reference and timings, in frame order.
///
/// The error type is the caller's (anything weft-nn's [`Error`] converts into), so that
/// `on_frame` can fail with its own errors (writing a file, say) without a wrapper.
pub fn run_against_reference<E: From<Error>>(
    runtime: &mut NnWarpSimulation,
    mut twins: Option<ReferenceTwins<'_>>,
    frames: usize,
    mut on_frame: impl FnMut(&FrameView<'_>) -> std::result::Result<(), E>,
) -> std::result::Result<ReferenceReport, E> {
    // Displacements are positions minus each simulation's own rest positions.
    let rests: Option<(Vec<f64>, Vec<Vec<f64>>)> = twins.as_ref().map(|t| {
        (
            t.reference.mesh().flat_positions(),
            t.others.iter().map(|s| s.mesh().flat_positions()).collect(),
        )
    });
    let displacement = |x: &[f64], rest: &[f64]| -> Vec<f64> { x.iter().zip(rest).map(|(x, r)| x - r).collect() };
    let mut report = ReferenceReport {
        frames: Vec::with_capacity(frames),
    };
    for k in 1..=frames {
        let step = runtime.step()?;
        let mut errors = FrameErrors {
            frame: k,
            solve_seconds: step.solve_seconds,
            warp_seconds: step.warp_seconds,
            reference_seconds: None,
            nnwarp: None,
            linear_solve: None,
            others: Vec::new(),
        };
        let (mut reference, mut others) = (None, Vec::new());
        if let (Some(t), Some((rest, other_rests))) = (&mut twins, &rests) {
            let start = Instant::now();
            let truth = displacement(&t.reference.step().map_err(Error::from)?.positions, rest);
            errors.reference_seconds = Some(start.elapsed().as_secs_f64());
            for (sim, rest) in t.others.iter_mut().zip(other_rests) {
                others.push(displacement(&sim.step().map_err(Error::from)?.positions, rest));
            }
            errors.nnwarp = Some(rel_error(&step.warped, &truth));
            errors.linear_solve = Some(rel_error(&step.linear, &truth));
            errors.others = others.iter().map(|u| rel_error(u, &truth)).collect();
            reference = Some(truth);
        }
        on_frame(&FrameView {
            frame: k,
            runtime: &step,
            reference: reference.as_deref(),
            others: &others,
        })?;
        report.frames.push(errors);
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nnwarp::{INPUTS, NodeMlp, OUTPUTS, Standardization, WarpMlp};
    use crate::params::ParamStore;
    use weft_sim::energies::Material;

    /// A small quick beam under gravity, its NNWarp runtime with an untrained network, and
    /// its linear-material twin.
    fn beam() -> (VolumeSimulation, VolumeSimulation, NodeMlp) {
        let mut scene = weft_sim::VolumeScene::builtin("beam-neo-hookean", true).unwrap();
        scene.frames = 3;
        let full = VolumeSimulation::new(scene.clone(), None).unwrap();
        let mut linear_scene = scene;
        linear_scene.material = Material::Linear;
        let linear = VolumeSimulation::new(linear_scene, None).unwrap();
        let standardization = Standardization {
            input_mean: [0.0; INPUTS],
            input_std: [1.0; INPUTS],
            output_mean: [0.0; OUTPUTS],
            output_std: [1.0; OUTPUTS],
        };
        let mut params = ParamStore::new(&candle_core::Device::Cpu, 3);
        let mlp = WarpMlp::new(&mut params, &[4], &standardization)
            .unwrap()
            .to_node_mlp(standardization)
            .unwrap();
        (full, linear, mlp)
    }

    #[test]
    fn the_loop_measures_every_displacement_against_the_reference_it_hands_out() {
        let (mut full, mut linear, mlp) = beam();
        let mut runtime = NnWarpSimulation::new(&full, mlp.clone()).unwrap();
        let mut seen = Vec::new();
        let report = run_against_reference(
            &mut runtime,
            Some(ReferenceTwins {
                reference: &mut full,
                others: vec![&mut linear],
            }),
            3,
            |f| -> Result<(), Error> {
                let truth = f.reference.expect("a reference");
                seen.push((
                    rel_error(&f.runtime.warped, truth),
                    rel_error(&f.runtime.linear, truth),
                    rel_error(&f.others[0], truth),
                ));
                Ok(())
            },
        )
        .unwrap();
        assert_eq!(report.frames.len(), 3);
        for (k, (f, s)) in report.frames.iter().zip(&seen).enumerate() {
            assert_eq!(f.frame, k + 1);
            assert_eq!(
                (f.nnwarp, f.linear_solve, f.others.clone()),
                (Some(s.0), Some(s.1), vec![s.2])
            );
            assert!(f.others[0] > 0.0, "linear FEM differs from neo-Hookean under gravity");
        }
        assert!(report.reference_seconds().is_some());
        // Without a reference the runtime alone runs, to the same displacements.
        let (full, _, _) = beam();
        let mut alone = NnWarpSimulation::new(&full, mlp).unwrap();
        let mut warped = Vec::new();
        let report = run_against_reference(&mut alone, None, 3, |f| -> Result<(), Error> {
            assert!(f.reference.is_none() && f.others.is_empty());
            warped.push(f.runtime.warped.clone());
            Ok(())
        })
        .unwrap();
        assert!(report.frames.iter().all(|f| f.nnwarp.is_none()));
        assert_eq!(report.reference_seconds(), None);
        assert_eq!(warped.len(), 3);
    }
}
