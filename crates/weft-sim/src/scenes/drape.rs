//! The drape scene (design §8): a sleeve on the posed limb, our analogue of Geng et al.'s
//! shirt on a posed body (§2, Fig. 1).
//!
//! - **Pose** `θ`: shoulder flexion, shoulder abduction and elbow flexion ([`ArmPose`],
//!   no bounce), drawn uniformly from the ranges of [`super::soft_tissue::SkeletalMotion`].
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

use crate::energies::{ConstantForce, DihedralBending, Membrane, ObstaclePenalty, ObstacleShape};
use crate::energy::Energy;
use crate::error::{Error, Result, check_positive};
use crate::newton::{HessianProjection, NewtonReport, NewtonSettings, NewtonSolver};
use crate::rng::SplitMix64;
use crate::scenes::soft_tissue::{
    ArmPose, BoneTransform, ELBOW_HALF_RANGE, ELBOW_MID, SHOULDER_RANGE, blend, forearm_weight,
};
use crate::scenes::volume::LimbResolution;

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
        Self {
            shoulder_flexion: rng.uniform(-SHOULDER_RANGE, SHOULDER_RANGE),
            shoulder_abduction: rng.uniform(-SHOULDER_RANGE, SHOULDER_RANGE),
            elbow_flexion: rng.uniform(ELBOW_MID - ELBOW_HALF_RANGE, ELBOW_MID + ELBOW_HALF_RANGE),
            bounce: 0.0,
        }
    }
    /// `[shoulder flexion, shoulder abduction, elbow flexion]` (rad): the network input.
    pub fn angles(&self) -> [f64; 3] {
        [self.shoulder_flexion, self.shoulder_abduction, self.elbow_flexion]
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
    sewn: Vec<usize>,
    membrane: Membrane,
    bending: DihedralBending,
    gravity: ConstantForce,
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
    pub report: NewtonReport,
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
        let topology = weft_mesh::Topology::new(&sleeve);
        let membrane = Membrane::new(&sleeve, params.young, params.poisson)?;
        let bending = DihedralBending::new(&sleeve, &topology, params.bend_stiffness)?;
        let masses = weft_mesh::geometry::lumped_masses_tri(sleeve.positions(), sleeve.faces(), params.density);
        let g = Vector3::from(params.gravity).norm();
        let max_weight = masses.iter().fold(0.0f64, |m, x| m.max(*x)) * g;
        let gravity = ConstantForce::gravity(&masses, params.gravity)?;
        Ok(Self {
            params,
            limb: limb_params,
            body,
            body_weights,
            sleeve,
            binding,
            sewn,
            membrane,
            bending,
            gravity,
            max_weight,
        })
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

    /// `r̃(θ)`: every sleeve vertex carried by its posed parent triangle (flat, m).
    pub fn kinematic_guess(&self, pose: &ArmPose) -> Vec<f64> {
        let body = self.skin(&pose.bone_transforms(&self.limb.joint_position()));
        self.guess_on(&body)
    }

    fn guess_on(&self, body: &[Vector3<f64>]) -> Vec<f64> {
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
        let posed = self.body(pose)?;
        let guess = self.guess_on(posed.positions());
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
            ..NewtonSettings::default()
        };
        let mut truth = guess.clone();
        let report = solver.minimize(&terms, &mut truth, &settings)?;
        Ok(DrapeExample {
            pose: *pose,
            guess,
            truth,
            report,
        })
    }
}
