//! Scenes: a TOML description of a cloth simulation (mesh, model, terms, grasp program,
//! time step) and the built-in scenes that reproduce Tan et al.'s datasets (§VI, design
//! §3). A scene builds only the terms it lists: without an `[obstacle]` table no contact
//! code is constructed or run.

use std::f64::consts::PI;

use nalgebra::{Rotation3, Vector3};
use serde::{Deserialize, Serialize};
use weft_mesh::{Topology, TriMesh, generators};

use crate::energies::{ConstantForce, DihedralBending, Membrane, ObstaclePenalty, ObstacleShape, Springs};
use crate::energy::Energy;
use crate::error::{Error, Result, check_positive};
use crate::guard::{Guard, GuardedFrame};
use crate::integrators::implicit_euler::{ImplicitEuler, StepReport};
use crate::newton::{Globalization, HessianProjection};
use crate::rng::SplitMix64;

/// Where the cloth mesh comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "generator", rename_all = "kebab-case", deny_unknown_fields)]
pub enum MeshSpec {
    /// `n × n` sheet of side `size` m, hung vertically in the XZ plane (centred at the origin).
    Sheet { n: usize, size: f64 },
    /// The 65-grid sheet with two holes (4165 vertices), hung vertically.
    SheetHoles { size: f64 },
    /// Closed UV sphere of radius `radius` m.
    Ball { segments: usize, rings: usize, radius: f64 },
    /// A triangle mesh from an OBJ file, used as is (metres).
    File { path: String },
}

/// The cloth material model and its parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ClothModel {
    /// Stretch springs on edges and bend springs to the 2-ring (Tan Fig. 1c); N/m.
    MassSpring {
        stretch_stiffness: f64,
        bend_stiffness: f64,
    },
    /// Green-strain linear membrane (2-D Young's modulus N/m, Poisson ratio) and
    /// dihedral-angle bending (N·m) (Tan Fig. 1d).
    Fem {
        young: f64,
        poisson: f64,
        bend_stiffness: f64,
    },
}

/// A static obstacle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ObstacleSpec {
    Sphere {
        center: [f64; 3],
        radius: f64,
        stiffness: f64,
        margin: f64,
    },
    Plane {
        point: [f64; 3],
        normal: [f64; 3],
        stiffness: f64,
        margin: f64,
    },
    Mesh {
        path: String,
        stiffness: f64,
        margin: f64,
    },
}

/// Which vertices are grasped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GraspVertices {
    /// The two top corners (highest Z, then lowest and highest X).
    TopCorners,
    /// The single highest vertex.
    Top,
    /// Explicit vertex indices.
    Indices(Vec<usize>),
}

/// A kind of grasp motion, and the frame label it produces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Motion {
    TranslateX,
    TranslateY,
    TranslateZ,
    /// Rotation of the grasp points about the vertical axis through their centroid.
    RotateZ,
}

/// One segment of the grasp program: `cycles` periods of `A sin(2π t / period)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionSegment {
    pub motion: Motion,
    /// Metres for translations, radians for rotations.
    pub amplitude: f64,
    /// Seconds.
    pub period: f64,
    pub cycles: f64,
}

/// The motion label of a frame (Tan et al. §VI-C classification: ±X, ±Y, ±R, ±Z).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MotionLabel {
    PlusX,
    MinusX,
    PlusY,
    MinusY,
    PlusZ,
    MinusZ,
    PlusR,
    MinusR,
}

impl MotionLabel {
    pub const ALL: [MotionLabel; 8] = [
        Self::PlusX,
        Self::MinusX,
        Self::PlusY,
        Self::MinusY,
        Self::PlusZ,
        Self::MinusZ,
        Self::PlusR,
        Self::MinusR,
    ];
    pub fn code(self) -> u8 {
        Self::ALL.iter().position(|&l| l == self).unwrap_or(0) as u8
    }
    pub fn as_str(self) -> &'static str {
        ["+X", "-X", "+Y", "-Y", "+Z", "-Z", "+R", "-R"][self.code() as usize]
    }
}

/// A complete cloth scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClothScene {
    pub name: String,
    #[serde(default)]
    pub description: String,
    pub mesh: MeshSpec,
    pub model: ClothModel,
    /// Areal density (kg/m²).
    pub density: f64,
    /// Gravitational acceleration (m/s²); omit or set to zero to build no gravity term.
    #[serde(default)]
    pub gravity: Option<[f64; 3]>,
    /// Multipliers of stretch and bending stiffness (Tan's 0.1·P_s and 0.1·P_b variants).
    #[serde(default = "one")]
    pub stretch_scale: f64,
    #[serde(default = "one")]
    pub bend_scale: f64,
    /// Time step (s).
    pub dt: f64,
    pub frames: usize,
    #[serde(default)]
    pub seed: u64,
    pub grasp: GraspVertices,
    /// The grasp program, repeated until `frames` are done.
    pub program: Vec<MotionSegment>,
    #[serde(default)]
    pub obstacle: Option<ObstacleSpec>,
    /// Newton tolerance as a fraction of the heaviest vertex's weight.
    #[serde(default = "default_rel_tol")]
    pub relative_tolerance: f64,
    #[serde(default = "default_max_iter")]
    pub max_newton_iterations: usize,
    /// Amplitude of the seeded displacement along the vertex normals that breaks the
    /// rest state's symmetry, as a fraction of the mean edge length (default 1e-6; 0
    /// turns it off). A flat sheet driven in its own plane is at an unstable equilibrium:
    /// without a deliberate perturbation, round-off (which differs between SIMD paths and
    /// factorisation orders) decides how it buckles, and frames differ between machines.
    #[serde(default = "default_symmetry_breaking")]
    pub symmetry_breaking: f64,
    /// How Newton makes an indefinite Hessian positive definite; omitted, the model's
    /// default: `never` (exact Hessian, smallest diagonal shift) for mass-spring, whose
    /// compressed springs wrinkle the sheet out of its symmetric state, and
    /// `when-indefinite` (exact, else per-element projection) for FEM (docs/CLOTH.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hessian: Option<HessianProjection>,
    /// Newton's globalisation (`line-search`, the default, or `trust-region`; see
    /// [`crate::newton::Globalization`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub globalization: Option<Globalization>,
    /// Switch a projected Newton solve to the shifted exact Hessian after this many
    /// consecutive iterations whose residual rose
    /// ([`crate::newton::NewtonSettings::exact_hessian_after_rises`]); omitted, never.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exact_hessian_after_rises: Option<usize>,
    /// Inexact steps: Newton iterations per time step, the last iterate accepted whatever
    /// its residual ([`crate::newton::NewtonSettings::iteration_budget`]; best with
    /// `hessian = "always"`, one factorisation per iteration); omitted, every step is
    /// solved to the tolerance. A speed–accuracy setting, not the ground truth's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub newton_budget: Option<usize>,
    /// Numeric factorisations per time step, at most; later iterations reuse the last
    /// factor (chord steps, [`crate::newton::NewtonSettings::factorization_budget`]).
    /// With `newton_budget`, inexact steps of one factorisation and a few solves; not
    /// with the trust region. Omitted, every iteration may factorise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub newton_factorizations: Option<usize>,
}

fn one() -> f64 {
    1.0
}
fn default_rel_tol() -> f64 {
    1e-3
}
fn default_symmetry_breaking() -> f64 {
    1e-6
}

/// Newton's iteration cap per step. Most frames take 3–40 iterations, but the first
/// frame of a flat mass-spring sheet leaves its symmetric saddle to wrinkle (180 on the
/// 65 × 65 `sheet-ms`). The cap bounds a failing step's cost, it does not slow
/// converging ones.
fn default_max_iter() -> usize {
    300
}

/// Names of the built-in scenes (design §3): the eight of Tan et al.'s SHEET and BALL
/// datasets first (the `embed` evaluation relies on this order), then the coarser sheets.
pub const BUILTIN_SCENES: [&str; 10] = [
    "sheet-ms",
    "sheet-ms-holes",
    "sheet-fem",
    "sheet-fem-obstacle",
    "ball-ms",
    "ball-fem",
    "ball-fem-soft-stretch",
    "ball-fem-soft-bend",
    "sheet-ms-33",
    "sheet-ms-17",
];

fn sheet_program() -> Vec<MotionSegment> {
    // Back and forth along ±X, ±Y, then a twist ±R about the vertical axis (Tan §VI).
    vec![
        MotionSegment {
            motion: Motion::TranslateX,
            amplitude: 0.15,
            period: 2.0,
            cycles: 2.0,
        },
        MotionSegment {
            motion: Motion::TranslateY,
            amplitude: 0.15,
            period: 2.0,
            cycles: 2.0,
        },
        MotionSegment {
            motion: Motion::RotateZ,
            amplitude: 0.6,
            period: 2.0,
            cycles: 2.0,
        },
    ]
}

fn ball_program() -> Vec<MotionSegment> {
    vec![MotionSegment {
        motion: Motion::TranslateZ,
        amplitude: 0.1,
        period: 1.0,
        cycles: 1.0,
    }]
}

const MASS_SPRING: ClothModel = ClothModel::MassSpring {
    stretch_stiffness: 1000.0,
    bend_stiffness: 20.0,
};
const FEM: ClothModel = ClothModel::Fem {
    young: 1000.0,
    poisson: 0.3,
    bend_stiffness: 1e-4,
};

impl ClothScene {
    /// A built-in scene by name; `quick` shrinks the mesh and frame count for tests.
    pub fn builtin(name: &str, quick: bool) -> Result<ClothScene> {
        let sheet = |n| {
            if quick {
                MeshSpec::Sheet { n: 9, size: 1.0 }
            } else {
                MeshSpec::Sheet { n, size: 1.0 }
            }
        };
        let ball = || {
            if quick {
                MeshSpec::Ball {
                    segments: 12,
                    rings: 8,
                    radius: 0.25,
                }
            } else {
                MeshSpec::Ball {
                    segments: 48,
                    rings: 32,
                    radius: 0.25,
                }
            }
        };
        let base = |mesh, model: ClothModel, frames, grasp, program| ClothScene {
            name: name.to_string(),
            description: String::new(),
            mesh,
            model,
            density: 0.2,
            gravity: Some([0.0, 0.0, -9.81]),
            stretch_scale: 1.0,
            bend_scale: 1.0,
            dt: 0.02,
            frames: if quick { 30 } else { frames },
            seed: 0,
            grasp,
            program,
            obstacle: None,
            relative_tolerance: default_rel_tol(),
            symmetry_breaking: default_symmetry_breaking(),
            hessian: None,
            globalization: None,
            exact_hessian_after_rises: None,
            newton_budget: None,
            newton_factorizations: None,
            max_newton_iterations: default_max_iter(),
        };
        let mut s = match name {
            "sheet-ms" => base(sheet(65), MASS_SPRING, 2400, GraspVertices::TopCorners, sheet_program()),
            "sheet-ms-33" => base(sheet(33), MASS_SPRING, 2400, GraspVertices::TopCorners, sheet_program()),
            "sheet-ms-17" => base(sheet(17), MASS_SPRING, 2400, GraspVertices::TopCorners, sheet_program()),
            "sheet-ms-holes" => base(
                if quick {
                    sheet(9)
                } else {
                    MeshSpec::SheetHoles { size: 1.0 }
                },
                MASS_SPRING,
                2400,
                GraspVertices::TopCorners,
                sheet_program(),
            ),
            "sheet-fem" | "sheet-fem-obstacle" => {
                base(sheet(65), FEM, 2400, GraspVertices::TopCorners, sheet_program())
            }
            "ball-ms" => base(ball(), MASS_SPRING, 500, GraspVertices::Top, ball_program()),
            "ball-fem" | "ball-fem-soft-stretch" | "ball-fem-soft-bend" => {
                base(ball(), FEM, 500, GraspVertices::Top, ball_program())
            }
            other => {
                return Err(Error::Scene(format!(
                    "unknown built-in scene {other:?}; built-ins are: {}",
                    BUILTIN_SCENES.join(", ")
                )));
            }
        };
        match name {
            "sheet-fem-obstacle" => {
                // A sphere in front of the curtain: the ±Y swings press the cloth into it.
                s.obstacle = Some(ObstacleSpec::Sphere {
                    center: [0.0, 0.3, -0.25],
                    radius: 0.2,
                    stiffness: 1e4,
                    margin: 0.005,
                });
            }
            "ball-fem-soft-stretch" => s.stretch_scale = 0.1,
            "ball-fem-soft-bend" => s.bend_scale = 0.1,
            _ => {}
        }
        s.description = format!(
            "built-in scene {name}{}: Tan et al. dataset analogue (design §3)",
            if quick { " (quick)" } else { "" }
        );
        Ok(s)
    }

    /// Parses a scene from TOML text.
    pub fn from_toml(text: &str) -> Result<ClothScene> {
        let s: ClothScene = toml::from_str(text).map_err(|e| Error::Scene(format!("invalid scene TOML: {e}")))?;
        s.validate()?;
        Ok(s)
    }

    /// The resolved scene as TOML.
    pub fn to_toml(&self) -> Result<String> {
        toml::to_string_pretty(self).map_err(|e| Error::Scene(format!("cannot serialise scene: {e}")))
    }

    /// Checks every parameter that does not need the mesh.
    pub fn validate(&self) -> Result<()> {
        check_positive("dt (s)", self.dt)?;
        check_positive("density (kg/m²)", self.density)?;
        check_positive("stretch_scale", self.stretch_scale)?;
        check_positive("bend_scale", self.bend_scale)?;
        check_positive("relative_tolerance", self.relative_tolerance)?;
        if !(self.symmetry_breaking.is_finite() && (0.0..=1e-2).contains(&self.symmetry_breaking)) {
            return Err(Error::InvalidParameter {
                name: "symmetry_breaking",
                value: self.symmetry_breaking,
                reason: "must be in [0, 0.01] (a fraction of the mean edge length)",
            });
        }
        if self.frames == 0 {
            return Err(Error::Scene("frames must be at least 1".into()));
        }
        if self.max_newton_iterations == 0 {
            return Err(Error::Scene(
                "max_newton_iterations must be at least 1 (no step can be solved without one)".into(),
            ));
        }
        if self.newton_budget == Some(0) {
            return Err(Error::Scene(
                "newton_budget must be at least 1 (omit it to solve every step to the tolerance)".into(),
            ));
        }
        if self.newton_budget.is_some_and(|b| b > self.max_newton_iterations) {
            return Err(Error::Scene(format!(
                "newton_budget {} exceeds max_newton_iterations {}",
                self.newton_budget.unwrap_or(0),
                self.max_newton_iterations
            )));
        }
        if self.newton_factorizations == Some(0) {
            return Err(Error::Scene(
                "newton_factorizations must be at least 1 (omit it to factorise at every iteration)".into(),
            ));
        }
        if self.newton_factorizations.is_some() && self.globalization == Some(Globalization::TrustRegion) {
            return Err(Error::Scene(
                "newton_factorizations applies to the line search; the trust region keeps its factor by its own rule"
                    .into(),
            ));
        }
        if self.program.is_empty() {
            return Err(Error::Scene(
                "the grasp program needs at least one motion segment".into(),
            ));
        }
        for seg in &self.program {
            check_positive("motion period (s)", seg.period)?;
            check_positive("motion cycles", seg.cycles)?;
            // Each segment is an offset `A sin(2π t / T)` from rest; it ends back at the
            // rest offset only after a whole number of half periods. Anything else would
            // teleport the grasped vertices at the next segment boundary.
            if (2.0 * seg.cycles - (2.0 * seg.cycles).round()).abs() > 1e-9 {
                return Err(Error::InvalidParameter {
                    name: "motion cycles",
                    value: seg.cycles,
                    reason: "must be a multiple of 0.5 so that consecutive segments meet at the rest offset",
                });
            }
            if !seg.amplitude.is_finite() {
                return Err(Error::InvalidParameter {
                    name: "motion amplitude",
                    value: seg.amplitude,
                    reason: "must be finite",
                });
            }
        }
        if let Some(g) = self.gravity {
            if g.iter().any(|v| !v.is_finite()) {
                return Err(Error::Scene(format!("gravity {g:?} is not finite")));
            }
        }
        Ok(())
    }

    /// Builds the rest mesh (in scene coordinates).
    pub fn build_mesh(&self, base_dir: Option<&std::path::Path>) -> Result<TriMesh> {
        let vertical = |m: TriMesh| -> Result<TriMesh> {
            // Hang the generated sheet in the XZ plane: (x, y, 0) → (x, 0, y).
            let p = m.positions().iter().map(|p| Vector3::new(p.x, p.z, p.y)).collect();
            // The swap of two axes flips orientation; the normals then face −Y. Cloth
            // is two-sided, so this does not matter physically.
            Ok(m.with_positions(p)?)
        };
        Ok(match &self.mesh {
            MeshSpec::Sheet { n, size } => vertical(generators::sheet(*n, *size)?)?,
            MeshSpec::SheetHoles { size } => {
                vertical(generators::sheet_with_holes(65, *size, &generators::DEFAULT_HOLES)?)?
            }
            MeshSpec::Ball {
                segments,
                rings,
                radius,
            } => generators::ball(*segments, *rings, *radius)?,
            MeshSpec::File { path } => {
                let p = base_dir.map_or_else(|| std::path::PathBuf::from(path), |d| d.join(path));
                weft_mesh::io::read_obj(&p)?
            }
        })
    }
}

/// One simulated frame.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Flat positions `p_m` (m).
    pub positions: Vec<f64>,
    /// Prescribed grasp positions `q_m`, 3 per grasped vertex (m).
    pub controls: Vec<f64>,
    pub label: MotionLabel,
    pub report: StepReport,
}

/// A scene made runnable: mesh, energy terms, integrator and grasp program.
#[derive(Debug)]
pub struct ClothSimulation {
    scene: ClothScene,
    mesh: TriMesh,
    grasp: Vec<usize>,
    grasp_rest: Vec<Vector3<f64>>,
    integrator: ImplicitEuler,
    frame: usize,
    /// Per-segment amplitude jitter drawn from the seed (±10 %).
    jitter: Vec<f64>,
}

/// Whether `term` is one of the cloth's internal elastic terms, stretching `P_s` or
/// bending `P_b` (Tan et al. Eq. 3), rather than gravity, an obstacle or inertia: the
/// potential that cloth inverse kinematics minimises (Tan et al. §V-A).
pub fn is_cloth_elastic(term: &dyn Energy) -> bool {
    matches!(
        term.name(),
        "stretch springs" | "bend springs" | "membrane" | "dihedral bending"
    )
}

impl ClothSimulation {
    pub fn new(scene: ClothScene, base_dir: Option<&std::path::Path>) -> Result<Self> {
        scene.validate()?;
        let mesh = scene.build_mesh(base_dir)?;
        let topo = Topology::new(&mesh);
        let masses = weft_mesh::geometry::lumped_masses_tri(mesh.positions(), mesh.faces(), scene.density);
        let mut terms: Vec<Box<dyn Energy>> = Vec::new();
        match scene.model {
            ClothModel::MassSpring {
                stretch_stiffness,
                bend_stiffness,
            } => {
                let mut s = Springs::stretch(&mesh, &topo, stretch_stiffness)?;
                s.scale_stiffness(scene.stretch_scale);
                let mut b = Springs::bend_two_ring(&mesh, &topo, bend_stiffness)?;
                b.scale_stiffness(scene.bend_scale);
                terms.push(Box::new(s));
                terms.push(Box::new(b));
            }
            ClothModel::Fem {
                young,
                poisson,
                bend_stiffness,
            } => {
                let mut m = Membrane::new(&mesh, young, poisson)?;
                m.scale_stiffness(scene.stretch_scale);
                let mut b = DihedralBending::new(&mesh, &topo, bend_stiffness)?;
                b.scale_stiffness(scene.bend_scale);
                terms.push(Box::new(m));
                terms.push(Box::new(b));
            }
        }
        if let Some(g) = scene.gravity {
            if g.iter().any(|v| *v != 0.0) {
                terms.push(Box::new(ConstantForce::gravity(&masses, g)?));
            }
        }
        if let Some(o) = &scene.obstacle {
            let nv = mesh.num_vertices();
            let penalty = match o {
                ObstacleSpec::Sphere {
                    center,
                    radius,
                    stiffness,
                    margin,
                } => ObstaclePenalty::new(
                    ObstacleShape::Sphere {
                        center: Vector3::from(*center),
                        radius: *radius,
                    },
                    nv,
                    *stiffness,
                    *margin,
                )?,
                ObstacleSpec::Plane {
                    point,
                    normal,
                    stiffness,
                    margin,
                } => ObstaclePenalty::new(
                    ObstacleShape::Plane {
                        point: Vector3::from(*point),
                        normal: Vector3::from(*normal),
                    },
                    nv,
                    *stiffness,
                    *margin,
                )?,
                ObstacleSpec::Mesh {
                    path,
                    stiffness,
                    margin,
                } => {
                    let p = base_dir.map_or_else(|| std::path::PathBuf::from(path), |d| d.join(path));
                    let m = weft_mesh::io::read_obj(&p)?;
                    ObstaclePenalty::new(ObstacleShape::mesh(&m)?, nv, *stiffness, *margin)?
                }
            };
            terms.push(Box::new(penalty));
        }
        let grasp = resolve_grasp(&scene.grasp, &mesh)?;
        let mut fixed = vec![false; 3 * mesh.num_vertices()];
        for &v in &grasp {
            fixed[3 * v..3 * v + 3].iter_mut().for_each(|f| *f = true);
        }
        let grasp_rest = grasp.iter().map(|&v| mesh.positions()[v]).collect();
        // The seeded symmetry-breaking displacement (see `ClothScene::symmetry_breaking`):
        // uniform in ±amplitude along each free vertex's normal, from its own SplitMix64
        // stream so it does not depend on the motion jitter drawn below.
        let mut x0 = mesh.flat_positions();
        if scene.symmetry_breaking > 0.0 {
            let p = mesh.positions();
            let mean_edge =
                topo.edges.iter().map(|&[a, b]| (p[a] - p[b]).norm()).sum::<f64>() / topo.edges.len().max(1) as f64;
            let amplitude = scene.symmetry_breaking * mean_edge;
            let normals = weft_mesh::geometry::vertex_normals(p, mesh.faces());
            let mut rng = SplitMix64::new(scene.seed ^ 0x0005_EED0_F5E7);
            for (v, n) in normals.iter().enumerate() {
                let d = amplitude * (2.0 * rng.unit() - 1.0);
                if !fixed[3 * v] {
                    for k in 0..3 {
                        x0[3 * v + k] += d * n[k];
                    }
                }
            }
        }
        let mut integrator = ImplicitEuler::new(masses, scene.dt, x0, terms, fixed)?;
        let max_weight = integrator.masses().iter().fold(0.0f64, |m, x| m.max(*x)) * 9.81;
        integrator.settings.tolerance = scene.relative_tolerance * max_weight.max(1e-12);
        integrator.settings.max_iterations = scene.max_newton_iterations;
        integrator.settings.globalization = scene.globalization.unwrap_or_default();
        integrator.settings.exact_hessian_after_rises = scene.exact_hessian_after_rises;
        integrator.settings.iteration_budget = scene.newton_budget;
        integrator.settings.factorization_budget = scene.newton_factorizations;
        integrator.settings.projection = scene.hessian.unwrap_or(match scene.model {
            ClothModel::MassSpring { .. } => HessianProjection::Never,
            ClothModel::Fem { .. } => HessianProjection::WhenIndefinite,
        });
        let mut rng = SplitMix64::new(scene.seed);
        let jitter = scene
            .program
            .iter()
            .map(|_| 1.0 + 0.1 * (2.0 * rng.unit() - 1.0))
            .collect();
        Ok(Self {
            scene,
            mesh,
            grasp,
            grasp_rest,
            integrator,
            frame: 0,
            jitter,
        })
    }

    pub fn scene(&self) -> &ClothScene {
        &self.scene
    }
    pub fn mesh(&self) -> &TriMesh {
        &self.mesh
    }
    pub fn grasp_vertices(&self) -> &[usize] {
        &self.grasp
    }
    pub fn integrator(&self) -> &ImplicitEuler {
        &self.integrator
    }
    pub fn integrator_mut(&mut self) -> &mut ImplicitEuler {
        &mut self.integrator
    }
    /// The integrator alone, e.g. to evaluate `L_phys` of other frames (weft-nn's
    /// physics-based loss) after the scene is no longer stepped.
    pub fn into_integrator(self) -> ImplicitEuler {
        self.integrator
    }
    /// Frames simulated so far.
    pub fn frame_index(&self) -> usize {
        self.frame
    }

    /// Grasp positions and label at frame `m` (time `m·dt`): the program's segments in
    /// order, repeated. Positions are those at `m·dt`; the label is that of the grasp
    /// velocity over the frame, taken at its midpoint `(m − ½)·dt`, so a frame that ends
    /// on a segment boundary is labelled by the motion it actually contains.
    pub fn controls_at(&self, m: usize) -> (Vec<Vector3<f64>>, MotionLabel) {
        let (seg_index, t) = self.segment_at(m as f64 * self.scene.dt);
        let positions = self.grasp_positions(seg_index, t);
        let (label_seg, label_t) = self.segment_at((m as f64 - 0.5).max(0.0) * self.scene.dt);
        (positions, self.label(label_seg, label_t))
    }

    /// The program segment active at time `t` and the time into it.
    fn segment_at(&self, time: f64) -> (usize, f64) {
        let total: f64 = self.scene.program.iter().map(|s| s.period * s.cycles).sum();
        let mut t = time % total;
        for (i, s) in self.scene.program.iter().enumerate() {
            let len = s.period * s.cycles;
            if t < len || i + 1 == self.scene.program.len() {
                return (i, t);
            }
            t -= len;
        }
        (0, t)
    }

    fn grasp_positions(&self, seg_index: usize, t: f64) -> Vec<Vector3<f64>> {
        let seg = &self.scene.program[seg_index];
        let amp = seg.amplitude * self.jitter[seg_index];
        let offset = amp * (2.0 * PI / seg.period * t).sin();
        let centroid = self.grasp_rest.iter().sum::<Vector3<f64>>() / self.grasp_rest.len() as f64;
        match seg.motion {
            Motion::TranslateX | Motion::TranslateY | Motion::TranslateZ => {
                let axis = match seg.motion {
                    Motion::TranslateX => Vector3::x(),
                    Motion::TranslateY => Vector3::y(),
                    _ => Vector3::z(),
                };
                self.grasp_rest.iter().map(|p| p + axis * offset).collect()
            }
            Motion::RotateZ => {
                let r = Rotation3::from_axis_angle(&Vector3::z_axis(), offset);
                self.grasp_rest.iter().map(|p| centroid + r * (p - centroid)).collect()
            }
        }
    }

    /// The label of the grasp velocity `A ω cos(ω t)` of segment `seg_index` at time `t`.
    fn label(&self, seg_index: usize, t: f64) -> MotionLabel {
        let seg = &self.scene.program[seg_index];
        let amp = seg.amplitude * self.jitter[seg_index];
        let forward = (2.0 * PI / seg.period * t).cos() >= 0.0;
        let (plus, minus) = match seg.motion {
            Motion::TranslateX => (MotionLabel::PlusX, MotionLabel::MinusX),
            Motion::TranslateY => (MotionLabel::PlusY, MotionLabel::MinusY),
            Motion::TranslateZ => (MotionLabel::PlusZ, MotionLabel::MinusZ),
            Motion::RotateZ => (MotionLabel::PlusR, MotionLabel::MinusR),
        };
        if (amp >= 0.0) == forward { plus } else { minus }
    }

    /// The grasp of frame `m` as prescribed DOFs `(dof, value)` for the integrator.
    pub fn prescribed_at(&self, m: usize) -> Vec<(usize, f64)> {
        let (q, _) = self.controls_at(m);
        self.grasp
            .iter()
            .zip(&q)
            .flat_map(|(&v, p)| (0..3).map(move |k| (3 * v + k, p[k])))
            .collect()
    }

    /// Simulates the next frame.
    pub fn step(&mut self) -> Result<Frame> {
        let m = self.frame + 1;
        let (q, label) = self.controls_at(m);
        let prescribed = self.prescribed_at(m);
        let report = self.integrator.step(&prescribed)?;
        let positions = self.integrator.positions().to_vec();
        if let Some(i) = positions.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "simulated position",
                dof: i,
            });
        }
        self.frame = m;
        Ok(Frame {
            positions,
            controls: q.iter().flat_map(|p| [p.x, p.y, p.z]).collect(),
            label,
            report,
        })
    }

    /// The next frame under `guard`: its surrogate proposes it, the guard accepts or
    /// corrects it (see [`crate::guard`]); `reference` is the ground truth's frame, if
    /// known, for the report's true error.
    pub fn step_guarded(&mut self, guard: &mut Guard, reference: Option<&[f64]>) -> Result<GuardedFrame> {
        let m = self.frame + 1;
        let (q, label) = self.controls_at(m);
        let prescribed = self.prescribed_at(m);
        let report = guard.step(&mut self.integrator, m, &prescribed, reference)?;
        self.frame = m;
        Ok(GuardedFrame {
            positions: self.integrator.positions().to_vec(),
            controls: q.iter().flat_map(|p| [p.x, p.y, p.z]).collect(),
            label,
            report,
        })
    }
}

fn resolve_grasp(spec: &GraspVertices, mesh: &TriMesh) -> Result<Vec<usize>> {
    let p = mesh.positions();
    let n = p.len();
    let top = || {
        (0..n)
            .max_by(|&a, &b| p[a].z.total_cmp(&p[b].z).then(b.cmp(&a)))
            .unwrap_or(0)
    };
    Ok(match spec {
        GraspVertices::Top => vec![top()],
        GraspVertices::TopCorners => {
            let zmax = p[top()].z;
            let tol = 1e-9 * mesh.bounding_box_diagonal();
            let row: Vec<usize> = (0..n).filter(|&i| p[i].z >= zmax - tol).collect();
            let left = *row.iter().min_by(|&&a, &&b| p[a].x.total_cmp(&p[b].x)).unwrap_or(&0);
            let right = *row.iter().max_by(|&&a, &&b| p[a].x.total_cmp(&p[b].x)).unwrap_or(&0);
            if left == right { vec![left] } else { vec![left, right] }
        }
        GraspVertices::Indices(ix) => {
            if ix.is_empty() {
                return Err(Error::Scene("grasp index list is empty".into()));
            }
            if let Some(&bad) = ix.iter().find(|&&i| i >= n) {
                return Err(Error::VertexOutOfRange {
                    what: "grasp",
                    index: bad,
                    num_vertices: n,
                });
            }
            ix.clone()
        }
    })
}
