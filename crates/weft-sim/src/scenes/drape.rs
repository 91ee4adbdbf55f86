//! The drape scene (design §8): a sleeve on the posed limb, our analogue of Geng et al.'s
//! shirt on a posed body (§2, Fig. 1).
//!
//! - **Pose** `θ`: shoulder flexion, shoulder abduction, shoulder twist and elbow flexion
//!   ([`ArmPose`], no bounce), drawn uniformly from the scene's ranges (for the sleeve
//!   those of [`super::soft_tissue::SkeletalMotion`], without twist).
//! - **Body** `B(θ)`: the limb's boundary surface, linear-blend skinned by the two bones
//!   (the weights of [`forearm_weight`]).
//! - **Sleeve**: an open tube ([`weft_mesh::generators::tube`]) around the neutral limb
//!   (`θ = 0`) at `offset` outside its surface (the local radius plus `offset`). The ring
//!   at the shoulder end is sewn to the body: it follows the kinematic guess.
//! - **Kinematic guess** `r̃(θ)` (Geng et al. Fig. 1e): each sleeve vertex is bound at
//!   `θ = 0` to its closest point on the body surface — the triangle, the barycentric
//!   coordinates of the closest point, and the vertex's offset from it in the triangle's
//!   orthonormal frame — and follows the posed triangle.
//! - **Ground truth** `r(θ)`: FEM cloth (Green-strain membrane and dihedral bending,
//!   [`Membrane`], [`DihedralBending`]) at quasistatic equilibrium under gravity, with
//!   penalty contact against `B(θ)` as a triangle-mesh obstacle ([`ObstaclePenalty`]),
//!   found by Newton from `r̃(θ)`.
//!
//! Units: metres, kilograms, newtons.

use nalgebra::{Matrix3, Vector3};
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::PointQueryWithLocation;
use weft_mesh::TriMesh;
use weft_mesh::limb::{LimbParams, limb};

use crate::energies::{ConstantForce, DihedralBending, Inertia, Membrane, ObstaclePenalty, ObstacleShape};
use crate::energy::Energy;
use crate::error::{Error, Result, check_nonnegative, check_positive};
use crate::newton::{HessianProjection, NewtonReport, NewtonSettings, NewtonSolver};
use crate::rng::SplitMix64;
use crate::scenes::soft_tissue::{
    ArmPose, BoneTransform, ELBOW_HALF_RANGE, ELBOW_MID, SHOULDER_RANGE, blend, forearm_weight,
};
use crate::scenes::volume::LimbResolution;

/// Joint angles in a drape pose ([`ArmPose::angles`]), the width of the network's input.
pub const POSE_ANGLES: usize = 4;

/// Geometry, material and solver settings of the drape scene.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DrapeParams {
    /// The limb the sleeve is on.
    pub limb: LimbResolution,
    /// Sleeve vertices around the arm.
    pub sleeve_around: usize,
    /// Rings of the sleeve along the arm.
    pub sleeve_rings: usize,
    /// Along-arm extent of the sleeve (m; the shoulder is at 0, the elbow at 0.3, the
    /// wrist at 0.6).
    pub sleeve_start: f64,
    pub sleeve_end: f64,
    /// Gap between the neutral body surface and the sleeve (m).
    pub offset: f64,
    /// Gap at the sewn shoulder ring (m), widening to `offset` over `seam_ramp` m
    /// (a smoothstep) so the sleeve leaves the seam without a step.
    pub seam_offset: f64,
    pub seam_ramp: f64,
    /// 2-D Young's modulus (N/m) and Poisson ratio of the membrane.
    pub young: f64,
    pub poisson: f64,
    /// Dihedral bending stiffness (N·m).
    pub bend_stiffness: f64,
    /// Areal density (kg/m²).
    pub density: f64,
    /// Gravitational acceleration (m/s²).
    pub gravity: [f64; 3],
    /// Contact penalty stiffness per vertex (N/m) and margin (m).
    pub contact_stiffness: f64,
    pub contact_margin: f64,
    /// Newton stops when the largest free residual force is below this times the
    /// heaviest vertex's weight.
    pub relative_tolerance: f64,
    pub max_iterations: usize,
    /// Range of shoulder flexion and of abduction drawn for a pose: each in
    /// `±shoulder_range` (rad).
    #[serde(
        default = "default_shoulder_range",
        skip_serializing_if = "is_default_shoulder_range"
    )]
    pub shoulder_range: f64,
    /// Range `[lo, hi]` of elbow flexion drawn for a pose (rad).
    #[serde(default = "default_elbow_flexion", skip_serializing_if = "is_default_elbow_flexion")]
    pub elbow_flexion: [f64; 2],
    /// Range of shoulder twist (about the upper arm, turning the elbow's bend plane)
    /// drawn for a pose: `±twist_range` (rad). 0 (the sleeve's setting) draws none.
    #[serde(default, skip_serializing_if = "is_zero_f64")]
    pub twist_range: f64,
    /// Damped release before the equilibrium solve: this many proximal steps, each
    /// minimising the energy plus `Σ mᵢ‖x − x_k‖²/(2τ²)` from the previous one (implicit
    /// Euler steps from rest, velocities discarded), then Newton on the energy alone.
    /// 0 (the sleeve's setting) solves from the guess directly.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub settle_steps: usize,
    /// The settle steps' `τ` (s).
    #[serde(default, skip_serializing_if = "is_zero_f64")]
    pub settle_time_step: f64,
    /// Kinematic guess by skinning the sleeve itself with its own weights — a smoothstep
    /// from the upper arm to the forearm over ± this half-width (m) about the elbow —
    /// instead of binding each vertex to the body triangle under it. 0 (the sleeve's
    /// setting) binds. A sleeve centimetres off the arm needs it: bound to the body,
    /// its offsets turn with the body's crushed inner-elbow triangles and cross already
    /// at 0.5 rad of elbow flexion, while skinning with a blend wider than the body's
    /// keeps the guess unfolded over the scene's range (docs/DRAPE.md).
    #[serde(default, skip_serializing_if = "is_zero_f64")]
    pub skinned_guess_half_width: f64,
    /// Newton (settle steps and equilibrium) switches from the projected to the shifted
    /// exact Hessian after this many consecutive projected iterations in which the
    /// residual rose ([`NewtonSettings::exact_hessian_after_rises`]); 0 never switches,
    /// as the datasets made before it did. Both sleeves use 2: fewer iterations, fewer
    /// poses that do not converge, and the same equilibria where both converge
    /// (docs/DRAPE.md, "Leaving the saddles").
    #[serde(default, skip_serializing_if = "is_zero")]
    pub exact_hessian_after_rises: usize,
}

fn default_shoulder_range() -> f64 {
    SHOULDER_RANGE
}
fn is_default_shoulder_range(v: &f64) -> bool {
    *v == SHOULDER_RANGE
}
fn default_elbow_flexion() -> [f64; 2] {
    [ELBOW_MID - ELBOW_HALF_RANGE, ELBOW_MID + ELBOW_HALF_RANGE]
}
fn is_default_elbow_flexion(v: &[f64; 2]) -> bool {
    *v == default_elbow_flexion()
}
fn is_zero(v: &usize) -> bool {
    *v == 0
}
fn is_zero_f64(v: &f64) -> bool {
    *v == 0.0
}

impl DrapeParams {
    /// The standard sleeve: 48 × 63 = 3024 vertices (Geng et al.'s shirt has 2969), a
    /// short sleeve from the shoulder to 2 cm short of the elbow, on the default limb.
    ///
    /// The cloth is a soft, heavy knit (50 N/m, 1 kg/m²): the equilibrium depends on the
    /// ratio of weight to stiffness, and at this ratio the sleeve sags onto the arm. With
    /// the cloth scenes' 1000 N/m and 0.2 kg/m² the tube holds its own shape and barely
    /// moves. The sleeve stops short of the elbow crease: across a flexed elbow, sleeve
    /// vertices are caught between the upper-arm and forearm surfaces, where the penalty
    /// contact's closest point jumps from one to the other and Newton stalls
    /// (docs/DRAPE.md).
    ///
    /// The contact penalty is 1e3 N/m: the sleeve then sinks at most ~10 µm into the 3 mm
    /// margin, and Newton needs half the iterations it needs at 1e4 N/m (320 against 619
    /// over ten poses; `cargo run --release -p weft-sim --example drape_contact_stiffness`).
    pub fn standard() -> Self {
        Self {
            limb: LimbResolution::Default,
            sleeve_around: 48,
            sleeve_rings: 63,
            sleeve_start: 0.01,
            sleeve_end: 0.28,
            offset: 0.01,
            seam_offset: 0.004,
            seam_ramp: 0.06,
            young: 50.0,
            poisson: 0.3,
            bend_stiffness: 1e-5,
            density: 1.0,
            gravity: [0.0, 0.0, -9.81],
            contact_stiffness: 1e3,
            contact_margin: 0.003,
            relative_tolerance: 1e-2,
            max_iterations: 200,
            shoulder_range: SHOULDER_RANGE,
            elbow_flexion: default_elbow_flexion(),
            twist_range: 0.0,
            settle_steps: 0,
            settle_time_step: 0.0,
            skinned_guess_half_width: 0.0,
            exact_hessian_after_rises: 2,
        }
    }
    /// A 16 × 12 = 192-vertex sleeve on the quick limb, for tests.
    pub fn quick() -> Self {
        Self {
            limb: LimbResolution::Quick,
            sleeve_around: 16,
            sleeve_rings: 12,
            ..Self::standard()
        }
    }
    /// The loose sleeve (issue 33's garment that hangs): 64 × 47 = 3008 vertices from the
    /// shoulder to mid-forearm, 3 cm off the arm, so the slack hangs as a bag under the
    /// arm, slides along it as the arm tilts and folds at the elbow (docs/DRAPE.md, "The
    /// loose sleeve"). The shoulder turns ±1.3 rad, 2.6 times the sleeve's range: the arm
    /// tilts up to 74° either way, so the sleeve slides towards the hand or bunches at the
    /// seam. The shoulder also twists ±π/2 about the upper arm, so the elbow bends
    /// anywhere from straight down to sideways and gravity pulls the forearm's cloth
    /// across the elbow fold instead of always into it. (Abduction, about the vertical,
    /// turns the whole scene rigidly about the gravity axis; the drape depends on it only
    /// through that rotation.)
    ///
    /// A lighter, stiffer cloth than the sleeve's (150 N/m, 0.5 kg/m², bending 3e-5 N·m):
    /// its bending length `(B/ρg)^⅓` is about 1.8 cm, so folds span several edges, and it
    /// stretches millimetres, not centimetres, under its own weight. The guess skins the
    /// sleeve with its own weights, blended over ±10 cm about the elbow: bound to the body
    /// 3 cm off the skin, its inner-elbow offsets would cross from 0.5 rad of elbow
    /// flexion. Skinned, it stays unfolded up to 1.0 rad, the scene's range (it checks
    /// both ends of the elbow range when built; at 1.1 rad the inner elbow crushes). Newton
    /// starts after three settle steps of 0.05 s from the guess, which lower the sleeve
    /// onto the arm as a damped fall would instead of in one long Newton step: with them,
    /// starts 2 mm off the guess end on the same equilibrium, without them in others
    /// millimetres away (docs/DRAPE.md, "How unique the loose sleeve's equilibrium is").
    pub fn loose() -> Self {
        Self {
            sleeve_around: 64,
            sleeve_rings: 47,
            sleeve_start: 0.01,
            sleeve_end: 0.45,
            offset: 0.03,
            young: 150.0,
            bend_stiffness: 3e-5,
            density: 0.5,
            max_iterations: 400,
            shoulder_range: 1.3,
            elbow_flexion: [0.1, 1.0],
            twist_range: std::f64::consts::FRAC_PI_2,
            settle_steps: 3,
            settle_time_step: 0.05,
            skinned_guess_half_width: 0.1,
            ..Self::standard()
        }
    }
    /// The loose sleeve at 16 × 12 on the quick limb, for tests.
    pub fn loose_quick() -> Self {
        Self {
            limb: LimbResolution::Quick,
            sleeve_around: 16,
            sleeve_rings: 12,
            ..Self::loose()
        }
    }
    fn validate(&self) -> Result<()> {
        for (name, v) in [
            ("sleeve offset (m)", self.offset),
            ("seam offset (m)", self.seam_offset),
            ("seam ramp (m)", self.seam_ramp),
            ("membrane Young's modulus (N/m)", self.young),
            ("bending stiffness (N·m)", self.bend_stiffness),
            ("areal density (kg/m²)", self.density),
            ("contact stiffness (N/m)", self.contact_stiffness),
            ("contact margin (m)", self.contact_margin),
            ("relative tolerance", self.relative_tolerance),
        ] {
            check_positive(name, v)?;
        }
        if !(self.poisson.is_finite() && (0.0..0.5).contains(&self.poisson)) {
            return Err(Error::InvalidParameter {
                name: "Poisson ratio",
                value: self.poisson,
                reason: "must lie in [0, 0.5)",
            });
        }
        if self.sleeve_around < 3 || self.sleeve_rings < 2 {
            return Err(Error::Scene(format!(
                "the sleeve needs at least 3 vertices around and 2 rings, got {} and {}",
                self.sleeve_around, self.sleeve_rings
            )));
        }
        if self.seam_offset > self.offset {
            return Err(Error::Scene(format!(
                "the seam offset ({} m) must not exceed the sleeve's offset ({} m)",
                self.seam_offset, self.offset
            )));
        }
        if !self.gravity.iter().all(|g| g.is_finite()) || Vector3::from(self.gravity).norm() == 0.0 {
            return Err(Error::Scene(format!(
                "gravity must be finite and non-zero, got {:?}",
                self.gravity
            )));
        }
        let right = std::f64::consts::FRAC_PI_2;
        if !(self.shoulder_range.is_finite() && self.shoulder_range > 0.0 && self.shoulder_range <= right) {
            return Err(Error::InvalidParameter {
                name: "shoulder range (rad)",
                value: self.shoulder_range,
                reason: "must lie in (0, π/2]",
            });
        }
        if !(self.twist_range.is_finite() && (0.0..=right).contains(&self.twist_range)) {
            return Err(Error::InvalidParameter {
                name: "shoulder twist range (rad)",
                value: self.twist_range,
                reason: "must lie in [0, π/2]",
            });
        }
        let [lo, hi] = self.elbow_flexion;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi && hi <= right) {
            return Err(Error::Scene(format!(
                "the elbow flexion range must satisfy 0 ≤ lo < hi ≤ π/2 rad, got [{lo}, {hi}]"
            )));
        }
        if self.settle_steps > 0 {
            check_positive("settle time step (s)", self.settle_time_step)?;
        }
        check_nonnegative("skinned guess half-width (m)", self.skinned_guess_half_width)?;
        let length = self.limb.params().length;
        if !(0.0 < self.sleeve_start && self.sleeve_start < self.sleeve_end && self.sleeve_end < length) {
            return Err(Error::Scene(format!(
                "the sleeve must lie on the arm: need 0 < start < end < {length} m, got {} and {}",
                self.sleeve_start, self.sleeve_end
            )));
        }
        Ok(())
    }
}

impl ArmPose {
    /// A pose drawn uniformly from the ranges of `SkeletalMotion` at amplitude 1:
    /// shoulder flexion and abduction in ±0.5 rad, elbow flexion in [0.1, 1.3] rad, no
    /// bounce.
    pub fn sample(rng: &mut SplitMix64) -> Self {
        Self::sample_in(rng, SHOULDER_RANGE, 0.0, default_elbow_flexion())
    }
    /// A pose drawn uniformly with shoulder flexion and abduction in `±shoulder`, elbow
    /// flexion in `[elbow[0], elbow[1]]` and, when `twist` > 0, shoulder twist in
    /// `±twist` (rad), in that order, no bounce. With `twist` 0 nothing is drawn for it,
    /// so the stream of poses is the one drawn before the twist existed.
    pub fn sample_in(rng: &mut SplitMix64, shoulder: f64, twist: f64, elbow: [f64; 2]) -> Self {
        let shoulder_flexion = rng.uniform(-shoulder, shoulder);
        let shoulder_abduction = rng.uniform(-shoulder, shoulder);
        let elbow_flexion = rng.uniform(elbow[0], elbow[1]);
        let shoulder_twist = if twist > 0.0 { rng.uniform(-twist, twist) } else { 0.0 };
        Self {
            shoulder_flexion,
            shoulder_abduction,
            shoulder_twist,
            elbow_flexion,
            bounce: 0.0,
        }
    }
    /// `[shoulder flexion, shoulder abduction, shoulder twist, elbow flexion]` (rad):
    /// the network input.
    pub fn angles(&self) -> [f64; POSE_ANGLES] {
        [
            self.shoulder_flexion,
            self.shoulder_abduction,
            self.shoulder_twist,
            self.elbow_flexion,
        ]
    }
}

/// Where a sleeve vertex sits relative to the body at the neutral pose.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Binding {
    triangle: usize,
    barycentric: [f64; 3],
    /// Offset from the closest point in the triangle's frame `[e₁, e₂, n]`.
    local: Vector3<f64>,
}

/// Orthonormal frame `[e₁, e₂, n]` (columns) of a triangle: `e₁` along `b − a`, `n`
/// its unit normal.
fn triangle_frame(a: &Vector3<f64>, b: &Vector3<f64>, c: &Vector3<f64>) -> Matrix3<f64> {
    let e1 = (b - a).normalize();
    let n = (b - a).cross(&(c - a)).normalize();
    Matrix3::from_columns(&[e1, n.cross(&e1), n])
}

/// The drape scene, built once and solved per pose.
#[derive(Debug)]
pub struct Drape {
    params: DrapeParams,
    limb: LimbParams,
    body: TriMesh,
    body_weights: Vec<f64>,
    sleeve: TriMesh,
    binding: Vec<Binding>,
    /// The sleeve's own forearm weights when the guess skins it (empty when it binds).
    sleeve_weights: Vec<f64>,
    sewn: Vec<usize>,
    membrane: Membrane,
    bending: DihedralBending,
    gravity: ConstantForce,
    masses: Vec<f64>,
    max_weight: f64,
}

/// One solved example.
#[derive(Debug, Clone)]
pub struct DrapeExample {
    pub pose: ArmPose,
    /// `r̃(θ)`, flat (m).
    pub guess: Vec<f64>,
    /// `r(θ)`, flat (m).
    pub truth: Vec<f64>,
    /// The final equilibrium solve.
    pub report: NewtonReport,
    /// Newton iterations of the settle steps before it (0 without them).
    pub settle_iterations: usize,
}

impl Drape {
    pub fn new(params: DrapeParams) -> Result<Self> {
        params.validate()?;
        let limb_params = params.limb.params();
        let body = limb(&limb_params)?.mesh.boundary_surface()?.mesh;
        let body_weights = body
            .positions()
            .iter()
            .map(|x| forearm_weight(&limb_params, x))
            .collect();
        let radius = |x: f64| {
            let s = ((x - params.sleeve_start) / params.seam_ramp).clamp(0.0, 1.0);
            let gap = params.seam_offset + (params.offset - params.seam_offset) * s * s * (3.0 - 2.0 * s);
            limb_params.radius_at(x) + gap
        };
        let sleeve = weft_mesh::generators::tube(
            params.sleeve_around,
            params.sleeve_rings,
            params.sleeve_start,
            params.sleeve_end,
            radius,
        )?;
        let ObstacleShape::Mesh(parry_body) = ObstacleShape::mesh(&body)? else {
            unreachable!("ObstacleShape::mesh builds a mesh");
        };
        let p = body.positions();
        let binding = sleeve
            .positions()
            .iter()
            .map(|x| {
                let (proj, (triangle, location)) =
                    parry_body.project_local_point_and_get_location(PVec::new(x.x, x.y, x.z), false);
                let barycentric = location.barycentric_coordinates().ok_or_else(|| {
                    Error::Scene("a sleeve vertex projects into the body's solid, not onto its surface".into())
                })?;
                let [a, b, c] = body.faces()[triangle as usize];
                let closest = Vector3::new(proj.point.x, proj.point.y, proj.point.z);
                let frame = triangle_frame(&p[a], &p[b], &p[c]);
                Ok(Binding {
                    triangle: triangle as usize,
                    barycentric,
                    local: frame.transpose() * (x - closest),
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let sewn = (0..params.sleeve_around).collect();
        let sleeve_weights = if params.skinned_guess_half_width > 0.0 {
            let (joint, half) = (limb_params.joint * limb_params.length, params.skinned_guess_half_width);
            sleeve
                .positions()
                .iter()
                .map(|x| {
                    let s = ((x.x - (joint - half)) / (2.0 * half)).clamp(0.0, 1.0);
                    s * s * (3.0 - 2.0 * s)
                })
                .collect()
        } else {
            Vec::new()
        };
        let topology = weft_mesh::Topology::new(&sleeve);
        let membrane = Membrane::new(&sleeve, params.young, params.poisson)?;
        let bending = DihedralBending::new(&sleeve, &topology, params.bend_stiffness)?;
        let masses = weft_mesh::geometry::lumped_masses_tri(sleeve.positions(), sleeve.faces(), params.density);
        let g = Vector3::from(params.gravity).norm();
        let max_weight = masses.iter().fold(0.0f64, |m, x| m.max(*x)) * g;
        let gravity = ConstantForce::gravity(&masses, params.gravity)?;
        let drape = Self {
            params,
            limb: limb_params,
            body,
            body_weights,
            sleeve,
            binding,
            sleeve_weights,
            sewn,
            membrane,
            bending,
            gravity,
            masses,
            max_weight,
        };
        drape.check_guess()?;
        Ok(drape)
    }

    /// The guess must not fold the sleeve anywhere in the pose range: at both ends of
    /// the elbow range no triangle may turn over against the body triangle its first vertex is
    /// bound to (the sign of its normal along that triangle's normal changes from rest)
    /// or shrink below 0.3 of its rest area. A folded guess (offsets crossing on the
    /// inside of a bent elbow) would start Newton from a self-intersecting sleeve, and
    /// the scene has no self-contact.
    fn check_guess(&self) -> Result<()> {
        let faces = self.sleeve.faces();
        let normal = |p: &[Vector3<f64>], [a, b, c]: [usize; 3]| (p[b] - p[a]).cross(&(p[c] - p[a]));
        let body_normal = |p: &[Vector3<f64>], v: usize| {
            let [i, j, k] = self.body.faces()[self.binding[v].triangle];
            (p[j] - p[i]).cross(&(p[k] - p[i]))
        };
        let rest_body = self.body.positions();
        let rest = self.sleeve.positions();
        // Only the elbow matters: flexion, abduction and twist turn both bones, hence the
        // skinned body and the guess, by one rotation, which leaves every test below as is.
        for elbow_flexion in self.params.elbow_flexion {
            let pose = ArmPose {
                elbow_flexion,
                ..ArmPose::default()
            };
            let transforms = pose.bone_transforms(&self.limb.joint_position());
            let body = self.skin(&transforms);
            let guess: Vec<Vector3<f64>> = self
                .guess_on(&transforms, &body)
                .chunks(3)
                .map(|x| Vector3::new(x[0], x[1], x[2]))
                .collect();
            let folded = faces
                .iter()
                .filter(|&&f| {
                    let (n0, n) = (normal(rest, f), normal(&guess, f));
                    let side0 = n0.dot(&body_normal(rest_body, f[0]));
                    let side = n.dot(&body_normal(&body, f[0]));
                    side0 * side <= 0.0 || n.norm() < 0.3 * n0.norm()
                })
                .count();
            if folded > 0 {
                return Err(Error::Scene(format!(
                    "the kinematic guess folds {folded} sleeve triangles at elbow flexion {elbow_flexion} rad; \
                     narrow the elbow range or the offset"
                )));
            }
        }
        Ok(())
    }

    /// A pose drawn from the scene's ranges ([`DrapeParams::shoulder_range`],
    /// [`DrapeParams::twist_range`], [`DrapeParams::elbow_flexion`]); for the sleeve's
    /// defaults the same draw as [`ArmPose::sample`].
    pub fn sample_pose(&self, rng: &mut SplitMix64) -> ArmPose {
        let p = &self.params;
        ArmPose::sample_in(rng, p.shoulder_range, p.twist_range, p.elbow_flexion)
    }

    pub fn params(&self) -> &DrapeParams {
        &self.params
    }
    /// The sleeve at rest (the neutral pose, before draping).
    pub fn sleeve(&self) -> &TriMesh {
        &self.sleeve
    }
    /// The body surface at the neutral pose.
    pub fn body_rest(&self) -> &TriMesh {
        &self.body
    }
    /// The sleeve vertices sewn to the body (the shoulder-end ring).
    pub fn sewn(&self) -> &[usize] {
        &self.sewn
    }

    /// `B(θ)`: the skinned body surface.
    pub fn body(&self, pose: &ArmPose) -> Result<TriMesh> {
        let transforms = pose.bone_transforms(&self.limb.joint_position());
        Ok(self.body.with_positions(self.skin(&transforms))?)
    }

    fn skin(&self, transforms: &[BoneTransform; 2]) -> Vec<Vector3<f64>> {
        self.body
            .positions()
            .iter()
            .zip(&self.body_weights)
            .map(|(x, &w)| blend(x, w, transforms))
            .collect()
    }

    /// `r̃(θ)`: every sleeve vertex carried by its posed parent triangle, or skinned with
    /// the sleeve's own weights ([`DrapeParams::skinned_guess_half_width`]) (flat, m).
    pub fn kinematic_guess(&self, pose: &ArmPose) -> Vec<f64> {
        let transforms = pose.bone_transforms(&self.limb.joint_position());
        self.guess_on(&transforms, &self.skin(&transforms))
    }

    fn guess_on(&self, transforms: &[BoneTransform; 2], body: &[Vector3<f64>]) -> Vec<f64> {
        if !self.sleeve_weights.is_empty() {
            return self
                .sleeve
                .positions()
                .iter()
                .zip(&self.sleeve_weights)
                .flat_map(|(x, &w)| blend(x, w, transforms).data.0[0])
                .collect();
        }
        let faces = self.body.faces();
        self.binding
            .iter()
            .flat_map(|b| {
                let [i, j, k] = faces[b.triangle];
                let [u, v, w] = b.barycentric;
                let point = body[i] * u + body[j] * v + body[k] * w;
                let x = point + triangle_frame(&body[i], &body[j], &body[k]) * b.local;
                [x.x, x.y, x.z]
            })
            .collect()
    }

    /// The draped sleeve at `pose`: Newton on membrane + bending + gravity + contact
    /// against `B(θ)` from `r̃(θ)`, the sewn ring held at `r̃(θ)`.
    pub fn solve(&self, pose: &ArmPose) -> Result<DrapeExample> {
        self.solve_from(pose, None)
    }

    /// [`Self::solve`] from `start` instead of the guess (flat, m; the sewn ring is
    /// still held at the guess), to probe how unique the equilibrium is.
    pub fn solve_from(&self, pose: &ArmPose, start: Option<&[f64]>) -> Result<DrapeExample> {
        let transforms = pose.bone_transforms(&self.limb.joint_position());
        let posed = self.body.with_positions(self.skin(&transforms))?;
        let guess = self.guess_on(&transforms, posed.positions());
        let n = self.sleeve.num_vertices();
        let contact = ObstaclePenalty::new(
            ObstacleShape::mesh(&posed)?,
            n,
            self.params.contact_stiffness,
            self.params.contact_margin,
        )?;
        let terms: [&dyn Energy; 4] = [&self.membrane, &self.bending, &self.gravity, &contact];
        let fixed = crate::anchors::fixed_dofs(n, &self.sewn)?;
        let mut solver = NewtonSolver::new(3 * n, &terms, fixed)?;
        let settings = NewtonSettings {
            tolerance: self.params.relative_tolerance * self.max_weight,
            max_iterations: self.params.max_iterations,
            projection: HessianProjection::WhenIndefinite,
            // A pose that does not converge is replaced by the next draw (the datasets
            // record it), not retried with another strategy: the published datasets
            // were made so.
            retry_other_strategy: false,
            exact_hessian_after_rises: (self.params.exact_hessian_after_rises > 0)
                .then_some(self.params.exact_hessian_after_rises),
            ..NewtonSettings::default()
        };
        let mut truth = guess.clone();
        if let Some(start) = start {
            if start.len() != truth.len() {
                return Err(Error::LengthMismatch {
                    what: "drape start positions",
                    expected: truth.len(),
                    got: start.len(),
                });
            }
            for (v, (t, s)) in truth.chunks_mut(3).zip(start.chunks(3)).enumerate() {
                if !self.sewn.contains(&v) {
                    t.copy_from_slice(s);
                }
            }
        }
        let settle_iterations = self.settle(&terms, &mut truth, &settings)?;
        let report = solver.minimize(&terms, &mut truth, &settings)?;
        self.check_on_arm(&guess, &truth)?;
        Ok(DrapeExample {
            pose: *pose,
            guess,
            truth,
            report,
            settle_iterations,
        })
    }

    /// Rejects an equilibrium in which the sleeve has come off the arm: a vertex farther
    /// from its kinematic guess than half the sleeve's length. On a raised arm the loose
    /// sleeve has such equilibria — slid down and turned inside out over the sewn seam,
    /// hanging from the shoulder (vertices 0.86 m from the guess, where a sleeve on the
    /// arm stays within 0.09 m; docs/DRAPE.md) — which are not a garment on the body.
    fn check_on_arm(&self, guess: &[f64], truth: &[f64]) -> Result<()> {
        let limit = OFF_ARM_FRACTION * (self.params.sleeve_end - self.params.sleeve_start);
        let (vertex, distance) = farthest_from(guess, truth);
        if distance > limit {
            return Err(Error::GarmentOffBody {
                vertex,
                distance,
                limit,
            });
        }
        Ok(())
    }

    /// The damped release of [`DrapeParams::settle_steps`]: returns the Newton
    /// iterations it took. A settle step that stops short of its tolerance is kept —
    /// it only prepares the start of the equilibrium solve, which decides convergence.
    fn settle(&self, terms: &[&dyn Energy], x: &mut [f64], settings: &NewtonSettings) -> Result<usize> {
        if self.params.settle_steps == 0 {
            return Ok(0);
        }
        let mut inertia = Inertia::new(self.masses.clone(), self.params.settle_time_step, x)?;
        let fixed = crate::anchors::fixed_dofs(x.len() / 3, &self.sewn)?;
        let mut solver: Option<NewtonSolver> = None;
        let settle = NewtonSettings {
            max_iterations: 50,
            ..*settings
        };
        let mut iterations = 0;
        for _ in 0..self.params.settle_steps {
            inertia.set_history(x, x)?;
            let all: Vec<&dyn Energy> = terms.iter().copied().chain([&inertia as &dyn Energy]).collect();
            let solver = match &mut solver {
                Some(s) => s,
                None => solver.insert(NewtonSolver::new(x.len(), &all, fixed.clone())?),
            };
            match solver.minimize(&all, x, &settle) {
                Ok(r) => iterations += r.iterations,
                Err(Error::NotConverged { .. }) => iterations += settle.max_iterations,
                Err(e) => return Err(e),
            }
        }
        Ok(iterations)
    }
}

/// A sleeve vertex farther than this fraction of the sleeve's length from its kinematic
/// guess means the sleeve has come off the arm ([`Drape::solve`] rejects the pose).
pub const OFF_ARM_FRACTION: f64 = 0.5;

/// The vertex of `b` farthest from its place in `a` (flat, m) and that distance.
fn farthest_from(a: &[f64], b: &[f64]) -> (usize, f64) {
    a.chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(p, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
        .enumerate()
        .fold((0, 0.0), |best, (v, d)| if d > best.1 { (v, d) } else { best })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sleeve_off_the_arm_is_rejected_and_one_on_it_is_not() {
        let drape = Drape::new(DrapeParams::loose_quick()).unwrap();
        let pose = ArmPose::default();
        let transforms = pose.bone_transforms(&drape.limb.joint_position());
        let posed = drape.skin(&transforms);
        let guess = drape.guess_on(&transforms, &posed);
        let length = drape.params.sleeve_end - drape.params.sleeve_start;
        let mut truth = guess.clone();
        // A fold 0.4 of the sleeve's length deep is still a drape on the arm.
        truth[3 * 7 + 2] -= 0.4 * length;
        drape.check_on_arm(&guess, &truth).unwrap();
        // Vertex 11 hanging 0.6 of it below its place is off the arm.
        truth[3 * 11 + 2] -= 0.6 * length;
        match drape.check_on_arm(&guess, &truth) {
            Err(Error::GarmentOffBody {
                vertex,
                distance,
                limit,
            }) => {
                assert_eq!(vertex, 11);
                assert!((distance - 0.6 * length).abs() < 1e-12, "{distance}");
                assert!((limit - OFF_ARM_FRACTION * length).abs() < 1e-15, "{limit}");
            }
            other => panic!("expected GarmentOffBody, got {other:?}"),
        }
    }
}
