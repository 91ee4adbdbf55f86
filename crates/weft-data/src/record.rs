//! The one frame-recording driver: steps any scene kind and collects its frames as named
//! arrays plus per-frame solver statistics. `simulate`, `dataset` and `evaluate` all
//! record through [`Recorder`], so what a frame holds is decided in one place.

use std::collections::HashMap;
use std::time::Instant;

use indicatif::ProgressBar;
use serde::Serialize;
use weft_sim::scenes::soft_tissue::SoftTissue;
use weft_sim::{AnyScene, ClothSimulation, LoadedScene, MotionLabel, VolumeSimulation};

use crate::files::Array;

/// A runnable scene of any kind.
pub enum Recorder {
    Cloth(ClothSimulation),
    Volume(VolumeSimulation),
    SoftTissue(Box<SoftTissue>),
}

/// Solver statistics of one frame.
#[derive(Debug, Clone, Serialize)]
pub struct FrameStats {
    pub frame: usize,
    /// Cloth motion label (Tan et al. §VI-C), `null` for other kinds.
    pub label: Option<&'static str>,
    pub newton_iterations: usize,
    pub residual_n: f64,
    pub seconds: f64,
    pub potential_energy_j: Option<f64>,
    pub kinetic_energy_j: Option<f64>,
    /// Cloth only: Newton's numeric factorisations (every attempt: the unprojected one,
    /// the projected second attempt of `when-indefinite`, each diagonally shifted one),
    /// conjugate-gradient iterations and rejected trust-region steps, the strategy of a
    /// retried step (docs/CLOTH.md), and per iteration the residual and the diagonal shift.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub newton_detail: Option<NewtonDetail>,
}

/// Where a cloth frame's Newton iterations went.
#[derive(Debug, Clone, Serialize)]
pub struct NewtonDetail {
    pub factorizations: usize,
    pub cg_iterations: usize,
    pub rejected_steps: usize,
    pub fallback: Option<String>,
    /// The residual force after each iteration (N).
    pub residual_history: Vec<f64>,
    /// The diagonal shift each line-search iteration stepped with (N/m; 0: none).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub shift_history: Vec<f64>,
    /// The first iteration on the shifted exact Hessian after a projected solve's switch
    /// (`NewtonSettings::exact_hessian_after_rises`), if it switched.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exact_from_iteration: Option<usize>,
    /// The step ended at the scene's `newton_budget` above the tolerance (an inexact
    /// step, accepted).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub stopped_at_budget: bool,
}

/// Every frame of a run, frame 0 being the initial (rest or settled) state.
#[derive(Debug)]
pub struct Recording {
    pub scene: String,
    /// Vertices per frame of `positions` (the surface for soft tissue, all nodes otherwise).
    pub vertices: usize,
    /// `(name, flat data)`; each array holds `frames × width` values.
    pub arrays: Vec<(&'static str, usize, Vec<f64>)>,
    /// Cloth only: the motion label code per frame.
    pub labels: Option<Vec<u8>>,
    pub per_frame: Vec<FrameStats>,
    /// Why the run stopped early, if it did (the frames before it are kept).
    pub error: Option<String>,
    pub total_seconds: f64,
    /// Safetensors metadata describing the arrays.
    pub metadata: HashMap<String, String>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Cloth(_) => "Recorder::Cloth",
            Self::Volume(_) => "Recorder::Volume",
            Self::SoftTissue(_) => "Recorder::SoftTissue",
        })
    }
}

impl Recorder {
    pub fn new(loaded: &LoadedScene) -> crate::Result<Self> {
        let base = loaded.base_dir.as_deref();
        Ok(match &loaded.scene {
            AnyScene::Cloth(s) => Self::Cloth(ClothSimulation::new(s.clone(), base)?),
            AnyScene::Volume(s) => Self::Volume(VolumeSimulation::new(s.clone(), base)?),
            AnyScene::SoftTissue(s) => Self::SoftTissue(Box::new(s.build()?)),
        })
    }

    /// The surface that recorded positions index, at rest: all vertices of a cloth mesh,
    /// the boundary surface of a soft-tissue body. Volumes record every node, which no
    /// triangle surface indexes; they have none.
    pub fn rest_surface(&self) -> Option<&weft_mesh::TriMesh> {
        match self {
            Self::Cloth(s) => Some(s.mesh()),
            Self::Volume(_) => None,
            Self::SoftTissue(s) => Some(&s.surface().mesh),
        }
    }

    /// Positions recorded per frame (flat, m): all vertices for cloth and volumes, the
    /// boundary surface `Y_t` for soft tissue.
    pub fn positions(&self) -> Vec<f64> {
        match self {
            Self::Cloth(s) => s.integrator().positions().to_vec(),
            Self::Volume(s) => s.positions().to_vec(),
            Self::SoftTissue(s) => s.simulated_surface(),
        }
    }

    fn empty_recording(&self, name: &str) -> Recording {
        let mut metadata = HashMap::new();
        metadata.insert("scene".into(), name.to_string());
        let (vertices, arrays, labels) = match self {
            Self::Cloth(s) => {
                let (q, label) = s.controls_at(0);
                metadata.insert("dt_s".into(), s.scene().dt.to_string());
                metadata.insert(
                    "units".into(),
                    "positions [frames, vertices, 3] and controls [frames, grasped, 3] in metres; labels [frames] \
                     u8 codes; frame 0 is the rest state"
                        .into(),
                );
                metadata.insert(
                    "labels".into(),
                    MotionLabel::ALL
                        .iter()
                        .map(|l| format!("{}={}", l.code(), l.as_str()))
                        .collect::<Vec<_>>()
                        .join(","),
                );
                metadata.insert(
                    "grasp_vertices".into(),
                    serde_json::to_string(s.grasp_vertices()).unwrap_or_default(),
                );
                let controls = q.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
                (
                    s.mesh().num_vertices(),
                    vec![
                        ("positions", 3 * s.mesh().num_vertices(), self.positions()),
                        ("controls", 3 * q.len(), controls),
                    ],
                    Some(vec![label.code()]),
                )
            }
            Self::Volume(s) => {
                metadata.insert(
                    "units".into(),
                    "positions and displacements [frames, nodes, 3] in metres; frame 0 is the rest state".into(),
                );
                metadata.insert("anchors".into(), serde_json::to_string(s.anchors()).unwrap_or_default());
                let n = s.mesh().num_vertices();
                (
                    n,
                    vec![
                        ("positions", 3 * n, self.positions()),
                        ("displacements", 3 * n, vec![0.0; 3 * n]),
                    ],
                    None,
                )
            }
            Self::SoftTissue(s) => {
                metadata.insert(
                    "units".into(),
                    "metres; skinned = X_t (kinematics only), simulated = positions = Y_t (Neo-Hookean), \
                     [frames, surface vertices, 3], same vertex order as rest.obj"
                        .into(),
                );
                metadata.insert("frame_dt_s".into(), s.params().frame_dt.to_string());
                let y = s.simulated_surface();
                (
                    y.len() / 3,
                    vec![
                        ("positions", y.len(), y.clone()),
                        ("skinned", y.len(), s.skinned_surface()),
                        ("simulated", y.len(), y),
                    ],
                    None,
                )
            }
        };
        Recording {
            scene: name.to_string(),
            vertices,
            arrays,
            labels,
            per_frame: Vec::new(),
            error: None,
            total_seconds: 0.0,
            metadata,
        }
    }

    /// Advances one frame and appends it to `rec`.
    fn step_into(&mut self, rec: &mut Recording) -> crate::Result<()> {
        let frame = rec.per_frame.len() + 1;
        let stats = match self {
            Self::Cloth(s) => {
                let f = s.step()?;
                rec.arrays[0].2.extend_from_slice(&f.positions);
                rec.arrays[1].2.extend_from_slice(&f.controls);
                if let Some(l) = rec.labels.as_mut() {
                    l.push(f.label.code());
                }
                FrameStats {
                    frame,
                    label: Some(f.label.as_str()),
                    newton_iterations: f.report.newton.iterations,
                    residual_n: f.report.newton.residual,
                    seconds: f.report.seconds,
                    potential_energy_j: Some(f.report.potential_energy),
                    kinetic_energy_j: Some(f.report.kinetic_energy),
                    newton_detail: Some(NewtonDetail {
                        factorizations: f.report.newton.factorizations,
                        cg_iterations: f.report.newton.cg_iterations,
                        rejected_steps: f.report.newton.rejected_steps,
                        fallback: f.report.newton.fallback.map(|h| format!("{h:?}")),
                        residual_history: f.report.newton.residual_history.clone(),
                        shift_history: f.report.newton.shift_history.clone(),
                        exact_from_iteration: f.report.newton.exact_from_iteration,
                        stopped_at_budget: f.report.newton.stopped_at_budget,
                    }),
                }
            }
            Self::Volume(s) => {
                let f = s.step()?;
                rec.arrays[0].2.extend_from_slice(&f.positions);
                let rest = s.mesh().positions();
                rec.arrays[1].2.extend(
                    f.positions
                        .chunks_exact(3)
                        .zip(rest)
                        .flat_map(|(p, r)| [p[0] - r.x, p[1] - r.y, p[2] - r.z]),
                );
                FrameStats {
                    frame,
                    label: None,
                    newton_iterations: f.iterations,
                    residual_n: f.residual,
                    seconds: f.seconds,
                    potential_energy_j: None,
                    kinetic_energy_j: None,
                    newton_detail: None,
                }
            }
            Self::SoftTissue(s) => {
                let r = s.step_frame()?;
                let y = s.simulated_surface();
                rec.arrays[0].2.extend_from_slice(&y);
                rec.arrays[1].2.extend(s.skinned_surface());
                rec.arrays[2].2.extend(y);
                FrameStats {
                    frame,
                    label: None,
                    newton_iterations: r.steps.iter().map(|s| s.newton.iterations).sum(),
                    residual_n: r.steps.last().map_or(0.0, |s| s.newton.residual),
                    seconds: r.seconds,
                    potential_energy_j: r.steps.last().map(|s| s.potential_energy),
                    kinetic_energy_j: r.steps.last().map(|s| s.kinetic_energy),
                    newton_detail: None,
                }
            }
        };
        rec.per_frame.push(stats);
        Ok(())
    }

    /// Records `frames` frames after the initial state. `on_frame` sees the recorder after
    /// each frame (for per-frame side outputs). A failed step ends the run early: the
    /// frames before it are kept and the error is stored in the recording.
    pub fn record(
        &mut self,
        name: &str,
        frames: usize,
        bar: &ProgressBar,
        mut on_frame: impl FnMut(usize, &Self) -> crate::Result<()>,
    ) -> crate::Result<Recording> {
        let mut rec = self.empty_recording(name);
        let start = Instant::now();
        for _ in 0..frames {
            if let Err(e) = self.step_into(&mut rec) {
                rec.error = Some(format!("frame {}: {e:#}", rec.per_frame.len() + 1));
                break;
            }
            on_frame(rec.per_frame.len(), self)?;
            bar.inc(1);
        }
        rec.total_seconds = start.elapsed().as_secs_f64();
        Ok(rec)
    }
}

impl Recording {
    /// Frames stored, the initial state included.
    pub fn frames(&self) -> usize {
        self.per_frame.len() + 1
    }

    /// The arrays in safetensors form (`[frames, rows, 3]`; labels as u8).
    pub fn to_arrays(&self) -> Vec<Array> {
        let f = self.frames();
        let mut out: Vec<Array> = self
            .arrays
            .iter()
            .map(|(name, width, data)| Array::f64(name, vec![f, width / 3, 3], data))
            .collect();
        if let Some(l) = &self.labels {
            out.push(Array::u8("labels", l));
        }
        out
    }

    /// Mean solver seconds per frame.
    pub fn seconds_per_frame(&self) -> f64 {
        // A fold from +0: an empty `sum::<f64>()` is −0, printed "-0.0" for a run stopped at frame 1.
        self.per_frame.iter().fold(0.0, |a, f| a + f.seconds) / self.per_frame.len().max(1) as f64
    }

    pub fn mean_newton_iterations(&self) -> f64 {
        self.per_frame.iter().fold(0.0, |a, f| a + f.newton_iterations as f64) / self.per_frame.len().max(1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recording_without_frames_has_zero_means_not_minus_zero() {
        let r = Recording {
            scene: "s".into(),
            vertices: 1,
            arrays: Vec::new(),
            labels: None,
            per_frame: Vec::new(),
            error: Some("stopped at frame 1".into()),
            total_seconds: 1.0,
            metadata: HashMap::new(),
        };
        for v in [r.seconds_per_frame(), r.mean_newton_iterations()] {
            assert_eq!(v, 0.0);
            assert!(v.is_sign_positive(), "{v} prints as {v:.1}");
        }
    }
}
