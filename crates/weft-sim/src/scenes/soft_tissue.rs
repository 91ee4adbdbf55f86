//! The soft-tissue dataset generator of design §6 (the Alt-ConvLSTM setting): a
//! [`weft_mesh::limb::Limb`] whose bone nodes follow two rigid bones driven by a smooth
//! random skeletal motion, with Neo-Hookean tissue (NNWarp Eq. 8) integrated by implicit
//! Euler under gravity.
//!
//! Each frame yields two surfaces in the same vertex order (the limb's boundary surface):
//! - `X_t`, the *skinned* surface: linear-blend skinning of the rest surface by the bone
//!   transforms — kinematics only, the SMPL analogue;
//! - `Y_t`, the *simulated* surface: the FEM solution with dynamics — the scanned-tissue
//!   analogue, which lags, sags and jiggles around `X_t`.
//!
//! Units: metres, seconds, kilograms, pascals.

use nalgebra::{Rotation3, Vector3};
use weft_mesh::BoundarySurface;
use weft_mesh::limb::{Limb, LimbParams, limb};

use crate::energies::{ConstantForce, LameParameters, Material, TetElasticity};
use crate::energy::Energy;
use crate::error::{Error, Result, check_nonnegative, check_positive};
use crate::guard::{Guard, GuardedTissueFrame};
use crate::integrators::implicit_euler::{ImplicitEuler, StepReport};
use crate::newton::{NewtonSettings, NewtonSolver};
use crate::rng::SplitMix64;

/// Material, timing and motion settings of a soft-tissue sequence.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SoftTissueParams {
    /// Young's modulus of the tissue (Pa); soft tissue is of order 10⁴. With a `core`,
    /// the modulus of the tissue outside it (the fat layer).
    pub young: f64,
    pub poisson: f64,
    /// Tissue density (kg/m³).
    pub density: f64,
    /// Time between stored frames (s).
    pub frame_dt: f64,
    /// Implicit-Euler steps per frame.
    pub substeps: usize,
    /// Gravitational acceleration (m/s²).
    pub gravity: [f64; 3],
    /// Seed of the random skeletal motion.
    pub seed: u64,
    /// Scales every joint angle and the bounce of the motion (1 = the documented ranges).
    pub motion_amplitude: f64,
    /// A stiffer inner layer (muscle) around the bones; `None`: one material throughout.
    /// (Left out of a scene file when absent, as `motion` when smooth, so the `limb`
    /// scene's file, and the checksums of its datasets, are what they were before the
    /// fields existed.)
    #[serde(skip_serializing_if = "Option::is_none")]
    pub core: Option<CoreLayer>,
    /// How the skeleton moves.
    #[serde(skip_serializing_if = "MotionStyle::is_smooth")]
    pub motion: MotionStyle,
}

impl MotionStyle {
    fn is_smooth(&self) -> bool {
        *self == Self::Smooth
    }
}

/// The tissue's inner layer: elements whose rest centroid lies within `fraction` of the
/// local body radius from the limb's axis have Young's modulus `young` (Pa); the rest have
/// [`SoftTissueParams::young`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoreLayer {
    pub young: f64,
    pub fraction: f64,
}

/// The character of the skeletal motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MotionStyle {
    /// Smooth joint motions (0.2–1 Hz) and a walking bounce (±2 cm, 1.2–2 Hz).
    #[default]
    Smooth,
    /// Jumps and shakes with abrupt stops, the accelerations of Dynamic FAUST's sequences:
    /// joint motions at 0.5–2 Hz, a vertical bounce within ±5 cm at 2–4 Hz (three terms
    /// whose amplitudes sum to 5 cm; peak accelerations near 2 g), and the whole skeleton
    /// stopping dead every 0.4–0.9 s for 0.3–0.6 s
    /// (decelerating over [`STOP_RAMP`]), while the tissue swings on.
    Dynamic,
}

/// How long the skeleton of a [`MotionStyle::Dynamic`] motion takes to stop or restart (s).
pub const STOP_RAMP: f64 = 0.06;

impl Default for SoftTissueParams {
    fn default() -> Self {
        Self {
            young: 3e4,
            poisson: 0.45,
            density: 1070.0,
            frame_dt: 1.0 / 30.0,
            substeps: 2,
            gravity: [0.0, 0.0, -9.81],
            seed: 0,
            motion_amplitude: 1.0,
            core: None,
            motion: MotionStyle::Smooth,
        }
    }
}

impl SoftTissueParams {
    /// The `limb-jiggle` scene's tissue: a 30 kPa muscle core inside 60 % of the radius
    /// under a 4 kPa fat layer, six implicit-Euler substeps per frame (so the method's own
    /// damping leaves the swing of the fat layer visible for about a second), and the
    /// dynamic motion (docs/ALTCONV.md, *The `limb-jiggle` data*).
    pub fn jiggle() -> Self {
        Self {
            young: 1.5e3,
            substeps: 6,
            core: Some(CoreLayer {
                young: 3e4,
                fraction: 0.45,
            }),
            motion: MotionStyle::Dynamic,
            ..Self::default()
        }
    }
}

/// A smooth random signal `c + Σ_k a_k sin(2π f_k t + φ_k)`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Sinusoids {
    pub offset: f64,
    /// `(amplitude, frequency Hz, phase rad)` per term.
    pub terms: Vec<(f64, f64, f64)>,
}

impl Sinusoids {
    pub fn at(&self, t: f64) -> f64 {
        self.offset
            + self
                .terms
                .iter()
                .map(|(a, f, p)| a * (2.0 * std::f64::consts::PI * f * t + p).sin())
                .sum::<f64>()
    }
    /// Three terms with frequencies in `[f_lo, f_hi)` Hz and amplitudes summing to
    /// `total` (so the signal stays within `offset ± total`).
    fn random(rng: &mut SplitMix64, offset: f64, total: f64, f_lo: f64, f_hi: f64) -> Self {
        let raw: Vec<f64> = (0..3).map(|_| rng.uniform(0.2, 1.0)).collect();
        let sum: f64 = raw.iter().sum();
        let terms = raw
            .iter()
            .map(|w| {
                (
                    total * w / sum,
                    rng.uniform(f_lo, f_hi),
                    rng.uniform(0.0, 2.0 * std::f64::consts::PI),
                )
            })
            .collect();
        Self { offset, terms }
    }
}

/// A rigid transform `x ↦ R x + t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoneTransform {
    pub rotation: Rotation3<f64>,
    pub translation: Vector3<f64>,
}

impl BoneTransform {
    pub fn apply(&self, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotation * x + self.translation
    }
}

/// Largest shoulder flexion and abduction of [`SkeletalMotion`] at amplitude 1 (rad).
pub const SHOULDER_RANGE: f64 = 0.5;
/// Mid-range and half-range of elbow flexion of [`SkeletalMotion`] at amplitude 1 (rad).
pub const ELBOW_MID: f64 = 0.7;
pub const ELBOW_HALF_RANGE: f64 = 0.6;

/// A pose of the two-bone limb: the joint angles (rad) and the shoulder's vertical offset (m).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct ArmPose {
    /// About +Y.
    pub shoulder_flexion: f64,
    /// About +Z.
    pub shoulder_abduction: f64,
    /// About the upper arm's long axis (+X at rest), before flexion and abduction: it
    /// turns the plane the elbow bends in, positive towards +Y. The drape's loose sleeve
    /// draws it; the limb's motions keep it 0.
    #[serde(default)]
    pub shoulder_twist: f64,
    /// About +Y at the elbow; positive bends the forearm towards −Z (palm down).
    pub elbow_flexion: f64,
    /// Vertical shoulder offset (m).
    pub bounce: f64,
}

impl ArmPose {
    /// The transforms of the upper arm (bone 0, about the shoulder at the origin) and
    /// the forearm (bone 1, about the elbow at `elbow`, chained to bone 0).
    pub fn bone_transforms(&self, elbow: &Vector3<f64>) -> [BoneTransform; 2] {
        let mut r0 = Rotation3::from_axis_angle(&Vector3::z_axis(), self.shoulder_abduction)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), self.shoulder_flexion);
        // Skipped at 0 so the poses without twist keep their bits.
        if self.shoulder_twist != 0.0 {
            r0 *= Rotation3::from_axis_angle(&Vector3::x_axis(), self.shoulder_twist);
        }
        let t0 = Vector3::new(0.0, 0.0, self.bounce);
        let upper = BoneTransform {
            rotation: r0,
            translation: t0,
        };
        let re = Rotation3::from_axis_angle(&Vector3::y_axis(), self.elbow_flexion);
        let fore = BoneTransform {
            rotation: r0 * re,
            translation: r0 * (elbow - re * elbow) + t0,
        };
        [upper, fore]
    }
}

/// Linear-blend-skinning weight of the forearm at rest point `x` (the upper arm's is
/// `1 − w`): a smoothstep across the elbow gap, at least ±5 cm wide.
pub fn forearm_weight(limb: &LimbParams, x: &Vector3<f64>) -> f64 {
    let joint_x = limb.joint * limb.length;
    let half = (0.5 * limb.joint_gap).max(0.05);
    let s = ((x.x - (joint_x - half)) / (2.0 * half)).clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

/// Smooth random skeletal motion of the two-bone limb: shoulder flexion (about Y) and
/// abduction (about Z) within ±[`SHOULDER_RANGE`], elbow flexion in [`ELBOW_MID`] ± [`ELBOW_HALF_RANGE`], and
/// a vertical bounce of the shoulder within ±2 cm (walking-like, 1.2–2 Hz) — all scaled
/// by the motion amplitude. Joint frequencies are 0.2–1 Hz.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SkeletalMotion {
    pub shoulder_flexion: Sinusoids,
    pub shoulder_abduction: Sinusoids,
    pub elbow_flexion: Sinusoids,
    pub bounce: Sinusoids,
    /// `[start, end]` (s) of each stop of a dynamic motion, ascending; empty for a smooth one.
    pub holds: Vec<[f64; 2]>,
}

impl SkeletalMotion {
    pub fn random(seed: u64, amplitude: f64) -> Self {
        let mut rng = SplitMix64::new(seed ^ SEED_SALT);
        Self {
            shoulder_flexion: Sinusoids::random(&mut rng, 0.0, SHOULDER_RANGE * amplitude, 0.2, 1.0),
            shoulder_abduction: Sinusoids::random(&mut rng, 0.0, SHOULDER_RANGE * amplitude, 0.2, 1.0),
            elbow_flexion: Sinusoids::random(&mut rng, ELBOW_MID * amplitude, ELBOW_HALF_RANGE * amplitude, 0.2, 1.0),
            bounce: Sinusoids::random(&mut rng, 0.0, 0.02 * amplitude, 1.2, 2.0),
            holds: Vec::new(),
        }
    }

    /// A motion of `style` from `seed`.
    pub fn of_style(style: MotionStyle, seed: u64, amplitude: f64) -> Self {
        match style {
            MotionStyle::Smooth => Self::random(seed, amplitude),
            MotionStyle::Dynamic => Self::dynamic(seed, amplitude),
        }
    }

    /// [`MotionStyle::Dynamic`]: faster joints, a larger and faster bounce, and stops over
    /// the first [`DYNAMIC_HORIZON`] seconds.
    pub fn dynamic(seed: u64, amplitude: f64) -> Self {
        let mut rng = SplitMix64::new(seed ^ SEED_SALT ^ 0xD1A_0000);
        let shoulder_flexion = Sinusoids::random(&mut rng, 0.0, SHOULDER_RANGE * amplitude, 0.5, 2.0);
        let shoulder_abduction = Sinusoids::random(&mut rng, 0.0, SHOULDER_RANGE * amplitude, 0.5, 2.0);
        let elbow_flexion = Sinusoids::random(&mut rng, ELBOW_MID * amplitude, ELBOW_HALF_RANGE * amplitude, 0.5, 2.0);
        let bounce = Sinusoids::random(&mut rng, 0.0, 0.05 * amplitude, 2.0, 4.0);
        let mut holds = Vec::new();
        let mut t = 0.0;
        while t < DYNAMIC_HORIZON {
            t += rng.uniform(0.4, 0.9);
            let h = rng.uniform(0.3, 0.6);
            holds.push([t, t + h]);
            t += h;
        }
        Self {
            shoulder_flexion,
            shoulder_abduction,
            elbow_flexion,
            bounce,
            holds,
        }
    }

    /// The motion's own clock at time `t`: `t` less the time spent stopped, each stop
    /// entered and left over [`STOP_RAMP`] with the clock's rate going linearly 1 → 0 → 1
    /// (so positions stay continuous and velocities ramp).
    pub fn motion_time(&self, t: f64) -> f64 {
        let w = STOP_RAMP;
        let mut lost = 0.0;
        for &[a, b] in &self.holds {
            if t <= a {
                break;
            }
            let w = w.min(0.5 * (b - a));
            lost += if t >= b {
                b - a - w
            } else if t <= a + w {
                (t - a).powi(2) / (2.0 * w)
            } else if t <= b - w {
                0.5 * w + (t - a - w)
            } else {
                0.5 * w + (b - a - 2.0 * w) + (t - b + w) - (t - b + w).powi(2) / (2.0 * w)
            };
        }
        t - lost
    }

    /// The pose at time `t` (s).
    pub fn pose(&self, t: f64) -> ArmPose {
        let t = self.motion_time(t);
        ArmPose {
            shoulder_flexion: self.shoulder_flexion.at(t),
            shoulder_abduction: self.shoulder_abduction.at(t),
            shoulder_twist: 0.0,
            elbow_flexion: self.elbow_flexion.at(t),
            bounce: self.bounce.at(t),
        }
    }

    /// The bone transforms at time `t` (see [`ArmPose::bone_transforms`]).
    pub fn bone_transforms(&self, t: f64, elbow: &Vector3<f64>) -> [BoneTransform; 2] {
        self.pose(t).bone_transforms(elbow)
    }
}

/// How far ahead a dynamic motion's stops are drawn (s); after it the motion runs on.
pub const DYNAMIC_HORIZON: f64 = 120.0;

/// Mixed into the user's seed so that seed 0 is not SplitMix64's all-zero state.
const SEED_SALT: u64 = 0x5EED_0F71_55E0_0001;

/// Frame-by-frame simulator of a limb's soft tissue.
#[derive(Debug)]
pub struct SoftTissue {
    limb: Limb,
    surface: BoundarySurface,
    params: SoftTissueParams,
    motion: SkeletalMotion,
    /// Linear-blend-skinning weight of the forearm per node (the upper arm's is `1 − w`).
    forearm_weight: Vec<f64>,
    bone_nodes: Vec<usize>,
    rest: Vec<f64>,
    integrator: ImplicitEuler,
    frame: usize,
}

/// What one frame did: one report per implicit-Euler substep.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FrameReport {
    pub steps: Vec<StepReport>,
    /// Wall time of the frame (s).
    pub seconds: f64,
}

/// A simulated sequence: the surface connectivity and, per frame, the skinned surface
/// `X_t` and the simulated surface `Y_t` (flat, 3 per surface vertex, m).
#[derive(Debug, Clone)]
pub struct SoftTissueSequence {
    /// Faces of the surface over its own vertex numbering (outward oriented).
    pub faces: Vec<[usize; 3]>,
    /// Rest positions of the surface (flat, m).
    pub rest: Vec<f64>,
    pub skinned: Vec<Vec<f64>>,
    pub simulated: Vec<Vec<f64>>,
    /// Per frame after the first (frame 0 is the settled start).
    pub reports: Vec<FrameReport>,
}

impl SoftTissue {
    /// Builds the simulation for `limb` and settles it: bones posed at `t = 0`, tissue in
    /// static equilibrium under gravity (so a sequence starts at rest, not with a drop).
    pub fn new(limb: Limb, params: SoftTissueParams) -> Result<Self> {
        check_positive("tissue density", params.density)?;
        check_positive("frame time step", params.frame_dt)?;
        check_nonnegative("motion amplitude", params.motion_amplitude)?;
        if params.substeps == 0 {
            return Err(Error::InvalidParameter {
                name: "substeps per frame",
                value: 0.0,
                reason: "must be at least 1",
            });
        }
        let lame = LameParameters::from_young_poisson(params.young, params.poisson)?;
        let mesh = &limb.mesh;
        let nv = mesh.num_vertices();
        let surface = mesh.boundary_surface()?;
        let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), params.density);
        let elastic = TetElasticity::new(mesh, Material::NeoHookean, lame)?;
        // With a core layer, the elements split into two energies by their rest centroid's
        // distance from the axis (the limb lies along +x at rest).
        let layered: Option<[TetElasticity; 2]> = match params.core {
            None => None,
            Some(core) => {
                check_positive("core Young's modulus", core.young)?;
                if !(core.fraction > 0.0 && core.fraction < 1.0) {
                    return Err(Error::InvalidParameter {
                        name: "core fraction of the radius",
                        value: core.fraction,
                        reason: "must be in (0, 1)",
                    });
                }
                let p = limb.params;
                let (inner, outer): (Vec<[usize; 4]>, Vec<[usize; 4]>) = mesh.tets().iter().partition(|t| {
                    let c = t.iter().map(|&v| mesh.positions()[v]).sum::<Vector3<f64>>() / 4.0;
                    (c.y * c.y + c.z * c.z).sqrt() < core.fraction * p.radius_at(c.x)
                });
                let core_lame = LameParameters::from_young_poisson(core.young, params.poisson)?;
                Some([
                    TetElasticity::from_rest(mesh.positions(), &inner, Material::NeoHookean, core_lame)?,
                    TetElasticity::from_rest(mesh.positions(), &outer, Material::NeoHookean, lame)?,
                ])
            }
        };
        let gravity = ConstantForce::gravity(&masses, params.gravity)?;
        let bone_nodes = limb.all_bone_nodes();
        let fixed = crate::anchors::fixed_dofs(nv, &bone_nodes)?;
        let p = limb.params;
        let forearm_weight: Vec<f64> = mesh.positions().iter().map(|x| forearm_weight(&p, x)).collect();
        let motion = SkeletalMotion::of_style(params.motion, params.seed, params.motion_amplitude);
        let rest = mesh.flat_positions();
        let mut this_x = vec![0.0; 3 * nv];
        let transforms = motion.bone_transforms(0.0, &p.joint_position());
        skin(mesh.positions(), &forearm_weight, &transforms, &mut this_x);
        // Static settle at t = 0.
        {
            let terms: Vec<&dyn Energy> = match &layered {
                None => vec![&elastic, &gravity],
                Some([a, b]) => vec![a, b, &gravity],
            };
            let mut solver = NewtonSolver::new(3 * nv, &terms, fixed.clone())?;
            let weight = masses.iter().fold(0.0f64, |m, x| m.max(*x)) * 9.81;
            let settings = NewtonSettings {
                tolerance: 1e-6 * weight.max(1e-12),
                ..NewtonSettings::default()
            };
            solver.minimize(&terms, &mut this_x, &settings)?;
        }
        let integrator = ImplicitEuler::new(
            masses,
            params.frame_dt / params.substeps as f64,
            this_x,
            match layered {
                None => vec![Box::new(elastic), Box::new(gravity)],
                Some([a, b]) => vec![Box::new(a), Box::new(b), Box::new(gravity)],
            },
            fixed,
        )?;
        Ok(Self {
            limb,
            surface,
            params,
            motion,
            forearm_weight,
            bone_nodes,
            rest,
            integrator,
            frame: 0,
        })
    }

    pub fn limb(&self) -> &Limb {
        &self.limb
    }
    pub fn surface(&self) -> &BoundarySurface {
        &self.surface
    }
    pub fn motion(&self) -> &SkeletalMotion {
        &self.motion
    }
    pub fn params(&self) -> &SoftTissueParams {
        &self.params
    }
    /// The implicit-Euler integrator's Newton settings (the stability map tightens the
    /// tolerance to measure how far a converged frame is from a tighter one).
    pub fn newton_settings_mut(&mut self) -> &mut crate::newton::NewtonSettings {
        &mut self.integrator.settings
    }

    /// Frames advanced so far.
    pub fn frame(&self) -> usize {
        self.frame
    }
    /// Time of the current frame (s).
    pub fn time(&self) -> f64 {
        self.frame as f64 * self.params.frame_dt
    }
    /// All simulated node positions (flat, m).
    pub fn positions(&self) -> &[f64] {
        self.integrator.positions()
    }

    /// `X_t`: the linear-blend-skinned surface at the current frame.
    pub fn skinned_surface(&self) -> Vec<f64> {
        let transforms = self
            .motion
            .bone_transforms(self.time(), &self.limb.params.joint_position());
        let mut out = vec![0.0; 3 * self.surface.volume_vertex.len()];
        for (i, &v) in self.surface.volume_vertex.iter().enumerate() {
            let x = blend(&self.limb.mesh.positions()[v], self.forearm_weight[v], &transforms);
            out[3 * i..3 * i + 3].copy_from_slice(x.as_slice());
        }
        out
    }

    /// `Y_t`: the simulated surface at the current frame (same vertex order as `X_t`).
    pub fn simulated_surface(&self) -> Vec<f64> {
        let x = self.integrator.positions();
        self.surface
            .volume_vertex
            .iter()
            .flat_map(|&v| [x[3 * v], x[3 * v + 1], x[3 * v + 2]])
            .collect()
    }

    /// Advances one frame (`substeps` implicit-Euler steps with the bones moved to
    /// their poses at each substep's end time).
    pub fn step_frame(&mut self) -> Result<FrameReport> {
        let start = std::time::Instant::now();
        let steps = self.step_frame_with(|integrator, _, prescribed| integrator.step(prescribed))?;
        Ok(FrameReport {
            steps,
            seconds: start.elapsed().as_secs_f64(),
        })
    }

    /// The next frame's `substeps` steps, each taken by `step(integrator, s, prescribed)`
    /// with the bones prescribed at the substep's end time; `s` counts the integrator's
    /// steps since the settled start (1 for the first substep of frame 1). The one loop of
    /// [`SoftTissue::step_frame`] (`ImplicitEuler::step`) and of the guarded roll-out
    /// ([`SoftTissue::step_frame_guarded`]), so both prescribe the same bones.
    pub fn step_frame_with<R>(
        &mut self,
        mut step: impl FnMut(&mut ImplicitEuler, usize, &[(usize, f64)]) -> Result<R>,
    ) -> Result<Vec<R>> {
        // Not `with_capacity(substeps)`: the count comes from the user, and a typo must not
        // become one huge allocation.
        let mut steps = Vec::new();
        for k in 1..=self.params.substeps {
            let prescribed = self.substep_prescribed(k);
            let s = self.frame * self.params.substeps + k;
            steps.push(step(&mut self.integrator, s, &prescribed)?);
        }
        self.frame += 1;
        Ok(steps)
    }

    /// The bone DOFs `(dof, value)` (m) at the end of substep `k` (1..=`substeps`) of the
    /// next frame: each bone node carried rigidly by its bone's transform.
    pub fn substep_prescribed(&self, k: usize) -> Vec<(usize, f64)> {
        let transforms = self.motion.bone_transforms(
            substep_time(&self.params, self.frame, k),
            &self.limb.params.joint_position(),
        );
        let positions = self.limb.mesh.positions();
        self.bone_nodes
            .iter()
            .flat_map(|&v| {
                let b = self.limb.bone[v].expect("bone node without a bone");
                let x = transforms[b].apply(&positions[v]);
                [(3 * v, x.x), (3 * v + 1, x.y), (3 * v + 2, x.z)]
            })
            .collect()
    }

    /// The next frame under `guard` (docs/GUARD.md, "limb-jiggle"): per substep its
    /// surrogate proposes the step (`StepInput::frame` is the step count `s` of
    /// [`SoftTissue::step_frame_with`]), the guard accepts or corrects it with this
    /// sequence's integrator. `reference` is the ground truth's frame (all nodes), if
    /// known, for the last substep's true error.
    pub fn step_frame_guarded(&mut self, guard: &mut Guard, reference: Option<&[f64]>) -> Result<GuardedTissueFrame> {
        let start = std::time::Instant::now();
        let last = (self.frame + 1) * self.params.substeps;
        let reports = self.step_frame_with(|integrator, s, prescribed| {
            guard.step(integrator, s, prescribed, reference.filter(|_| s == last))
        })?;
        Ok(GuardedTissueFrame {
            reports,
            seconds: start.elapsed().as_secs_f64(),
        })
    }

    /// The implicit-Euler integrator (its state is every node's, bones included).
    pub fn integrator(&self) -> &ImplicitEuler {
        &self.integrator
    }

    /// Linear-blend-skinning weight of the forearm per node (the upper arm's is `1 − w`).
    pub fn forearm_weights(&self) -> &[f64] {
        &self.forearm_weight
    }

    /// Rest positions of all nodes (flat, m).
    pub fn rest_positions(&self) -> &[f64] {
        &self.rest
    }
}

/// The time (s) at the end of substep `k` of the frame after frame `frame`, as
/// [`SoftTissue::step_frame`] poses the bones: `frame · frame_dt + k · frame_dt / substeps`.
pub fn substep_time(params: &SoftTissueParams, frame: usize, k: usize) -> f64 {
    let dt = params.frame_dt / params.substeps as f64;
    frame as f64 * params.frame_dt + k as f64 * dt
}

/// Linear blend skinning of one point.
pub(crate) fn blend(x: &Vector3<f64>, w: f64, transforms: &[BoneTransform; 2]) -> Vector3<f64> {
    transforms[0].apply(x) * (1.0 - w) + transforms[1].apply(x) * w
}

fn skin(rest: &[Vector3<f64>], weights: &[f64], transforms: &[BoneTransform; 2], out: &mut [f64]) {
    for (v, (x, &w)) in rest.iter().zip(weights).enumerate() {
        out[3 * v..3 * v + 3].copy_from_slice(blend(x, w, transforms).as_slice());
    }
}

/// Simulates `frames` frames after the settled start of the limb of `limb_params`,
/// returning `frames + 1` skinned and simulated surfaces (frame 0 = the settled start)
/// and the per-frame step reports.
pub fn simulate_soft_tissue(
    limb_params: &LimbParams,
    params: &SoftTissueParams,
    frames: usize,
) -> Result<SoftTissueSequence> {
    let mut sim = SoftTissue::new(limb(limb_params)?, *params)?;
    let surface = sim.surface();
    let faces = surface.mesh.faces().to_vec();
    let rest = weft_mesh::flatten(surface.mesh.positions());
    let mut seq = SoftTissueSequence {
        faces,
        rest,
        skinned: vec![sim.skinned_surface()],
        simulated: vec![sim.simulated_surface()],
        reports: Vec::new(),
    };
    for _ in 0..frames {
        seq.reports.push(sim.step_frame()?);
        seq.skinned.push(sim.skinned_surface());
        seq.simulated.push(sim.simulated_surface());
    }
    Ok(seq)
}
