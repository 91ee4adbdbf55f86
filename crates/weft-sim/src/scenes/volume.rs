//! Volumetric scenes: a tetrahedral body (generated or a user's TetGen/VTK file) anchored
//! by a plane or an index list, loaded by gravity or an NNWarp force field (§3.2), and
//! solved dynamically (implicit Euler, Newmark), quasistatically with load stepping, or by
//! linear FEM with a pre-factorised system (NNWarp's runtime). Also the `limb`
//! soft-tissue scene (design §6). Like cloth scenes, only the listed terms are built.

use serde::{Deserialize, Serialize};
use weft_mesh::{TetMesh, generators, limb::LimbParams};

use crate::anchors;
use crate::energies::{ConstantForce, LameParameters, Material, TetElasticity};
use crate::energy::Energy;
use crate::error::{Error, Result, check_positive};
use crate::integrators::implicit_euler::ImplicitEuler;
use crate::integrators::newmark::Newmark;
use crate::integrators::prefactorized::{LinearSolve, PrefactorizedLinear, RayleighDamping};
use crate::integrators::quasistatic::Quasistatic;
use crate::scenes::soft_tissue::{SoftTissue, SoftTissueParams};

/// The `type` key of a volumetric scene file (`type = "volume"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum VolumeTag {
    Volume,
}

/// The `type` key of a soft-tissue scene file (`type = "soft-tissue"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SoftTissueTag {
    SoftTissue,
}

/// Where the tetrahedral mesh comes from (metres).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "generator", rename_all = "kebab-case", deny_unknown_fields)]
pub enum VolumeMeshSpec {
    Beam {
        cells: [usize; 3],
        size: [f64; 3],
    },
    TaperedBeam {
        cells: [usize; 3],
        size: [f64; 3],
        tip_scale: f64,
    },
    BentBeam {
        cells: [usize; 3],
        size: [f64; 3],
        angle: f64,
    },
    TBeam {
        cells: [usize; 3],
        size: [f64; 3],
    },
    /// A TetGen `.node`/`.ele` pair or a legacy VTK unstructured grid.
    File {
        path: String,
    },
}

/// Which nodes are anchored (held at their rest positions).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "by", rename_all = "kebab-case", deny_unknown_fields)]
pub enum AnchorSpec {
    /// Every node within `tolerance` (m) of the minimum of coordinate `axis` (0 = x).
    Min {
        axis: usize,
        tolerance: f64,
    },
    /// Every node within `tolerance` (m) of a plane.
    Plane {
        point: [f64; 3],
        normal: [f64; 3],
        tolerance: f64,
    },
    Indices {
        indices: Vec<usize>,
    },
}

/// An NNWarp body-force field (§3.2), as an acceleration (m/s²).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ForceField {
    Directional {
        direction: [f64; 3],
        acceleration: f64,
    },
    Circular {
        center: [f64; 3],
        axis: [f64; 3],
        acceleration: f64,
    },
}

/// How the body is solved; frames are time steps (dynamic) or load increments
/// (quasistatic, static linear: frame `k` carries `k/frames` of the load).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "kebab-case", deny_unknown_fields)]
pub enum VolumeSolve {
    ImplicitEuler {
        dt: f64,
    },
    Newmark {
        dt: f64,
        rayleigh_mass: f64,
        rayleigh_stiffness: f64,
    },
    Quasistatic,
    /// Linear elasticity, `K u = f`, `K` factorised once (NNWarp's runtime).
    StaticLinear,
    /// Linear elasticity, backward Euler with a constant pre-factorised matrix.
    DynamicLinear {
        dt: f64,
        rayleigh_mass: f64,
        rayleigh_stiffness: f64,
    },
}

/// A complete volumetric scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VolumeScene {
    #[serde(rename = "type")]
    pub tag: VolumeTag,
    pub name: String,
    #[serde(default)]
    pub description: String,
    pub mesh: VolumeMeshSpec,
    pub material: Material,
    /// Young's modulus (Pa).
    pub young: f64,
    pub poisson: f64,
    /// Density (kg/m³).
    pub density: f64,
    pub anchors: AnchorSpec,
    #[serde(default)]
    pub gravity: Option<[f64; 3]>,
    #[serde(default)]
    pub force_field: Option<ForceField>,
    pub solve: VolumeSolve,
    pub frames: usize,
}

/// Name of the built-in soft-tissue scene.
pub const SOFT_TISSUE_SCENE: &str = "limb";
/// The soft-tissue scene whose tissue moves: a soft fat layer over a stiffer core, jumps,
/// shakes and abrupt stops ([`crate::scenes::soft_tissue::SoftTissueParams::jiggle`]).
pub const JIGGLE_SCENE: &str = "limb-jiggle";
/// Both soft-tissue scenes.
pub const SOFT_TISSUE_SCENES: [&str; 2] = [SOFT_TISSUE_SCENE, JIGGLE_SCENE];

/// Built-in volumetric scenes: the clamped beam for each material under gravity, the
/// Neo-Hookean beam under a directional field, and the pre-factorised linear beam.
pub const BUILTIN_VOLUME_SCENES: [&str; 6] = [
    "beam-linear",
    "beam-corotational",
    "beam-stvk",
    "beam-neo-hookean",
    "beam-neo-hookean-field",
    "beam-static-linear",
];

impl VolumeScene {
    pub fn builtin(name: &str, quick: bool) -> Result<Self> {
        let cells = if quick { [6, 3, 3] } else { [12, 6, 6] };
        let material = match name {
            "beam-linear" | "beam-static-linear" => Material::Linear,
            "beam-corotational" => Material::CoRotational,
            "beam-stvk" => Material::StVK,
            "beam-neo-hookean" | "beam-neo-hookean-field" => Material::NeoHookean,
            other => {
                return Err(Error::Scene(format!(
                    "unknown built-in volume scene {other:?}; built-ins are: {}",
                    BUILTIN_VOLUME_SCENES.join(", ")
                )));
            }
        };
        let mut s = VolumeScene {
            tag: VolumeTag::Volume,
            name: name.into(),
            description: format!("built-in scene {name}: beam clamped at x = 0 (NNWarp §6 analogue)"),
            mesh: VolumeMeshSpec::Beam {
                cells,
                size: [1.0, 0.5, 0.5],
            },
            material,
            young: 1e6,
            poisson: 0.3,
            density: 1000.0,
            anchors: AnchorSpec::Min {
                axis: 0,
                tolerance: 1e-9,
            },
            gravity: Some([0.0, 0.0, -9.81]),
            force_field: None,
            solve: VolumeSolve::ImplicitEuler { dt: 0.01 },
            frames: if quick { 10 } else { 100 },
        };
        if name == "beam-neo-hookean-field" {
            s.gravity = None;
            s.force_field = Some(ForceField::Directional {
                direction: [0.0, 1.0, 1.0],
                acceleration: 30.0,
            });
        }
        if name == "beam-static-linear" {
            s.solve = VolumeSolve::StaticLinear;
        }
        Ok(s)
    }

    pub fn from_toml(text: &str) -> Result<Self> {
        let s: Self = toml::from_str(text).map_err(|e| Error::Scene(format!("invalid volume scene TOML: {e}")))?;
        s.validate()?;
        Ok(s)
    }

    pub fn to_toml(&self) -> Result<String> {
        toml::to_string_pretty(self).map_err(|e| Error::Scene(format!("cannot serialise scene: {e}")))
    }

    pub fn validate(&self) -> Result<()> {
        LameParameters::from_young_poisson(self.young, self.poisson)?;
        check_positive("density (kg/m³)", self.density)?;
        if self.frames == 0 {
            return Err(Error::Scene("frames must be at least 1".into()));
        }
        match self.solve {
            VolumeSolve::ImplicitEuler { dt }
            | VolumeSolve::Newmark { dt, .. }
            | VolumeSolve::DynamicLinear { dt, .. } => check_positive("dt (s)", dt),
            _ => Ok(()),
        }
    }

    pub fn build_mesh(&self, base_dir: Option<&std::path::Path>) -> Result<TetMesh> {
        let p = |cells: [usize; 3], size: [f64; 3]| generators::BeamParams { cells, size };
        Ok(match &self.mesh {
            VolumeMeshSpec::Beam { cells, size } => generators::beam(&p(*cells, *size))?,
            VolumeMeshSpec::TaperedBeam { cells, size, tip_scale } => {
                generators::tapered_beam(&p(*cells, *size), *tip_scale)?
            }
            VolumeMeshSpec::BentBeam { cells, size, angle } => generators::bent_beam(&p(*cells, *size), *angle)?,
            VolumeMeshSpec::TBeam { cells, size } => generators::t_beam(&p(*cells, *size))?,
            VolumeMeshSpec::File { path } => {
                let full = base_dir.map_or_else(|| std::path::PathBuf::from(path), |d| d.join(path));
                match weft_mesh::io::read_mesh(&full)? {
                    weft_mesh::io::AnyMesh::Volume(m) => m,
                    weft_mesh::io::AnyMesh::Surface(_) => {
                        return Err(Error::Scene(format!(
                            "{path} is a surface mesh; a volume scene needs tetrahedra"
                        )));
                    }
                }
            }
        })
    }
}

enum Solver {
    Euler(ImplicitEuler),
    Newmark(Newmark),
    Quasistatic {
        solver: Quasistatic,
        elastic: TetElasticity,
        x: Vec<f64>,
    },
    Linear(PrefactorizedLinear),
}

/// One frame of a volumetric simulation.
#[derive(Debug, Clone)]
pub struct VolumeFrame {
    /// Flat positions (m).
    pub positions: Vec<f64>,
    /// Newton iterations spent (0 for the pre-factorised linear solve).
    pub iterations: usize,
    /// Final residual force (N; 0 for the linear solve, which is exact).
    pub residual: f64,
    pub seconds: f64,
}

/// A volumetric scene made runnable.
pub struct VolumeSimulation {
    scene: VolumeScene,
    mesh: TetMesh,
    anchors: Vec<usize>,
    forces: Vec<f64>,
    solver: Solver,
    frame: usize,
}

impl std::fmt::Debug for VolumeSimulation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VolumeSimulation")
            .field("scene", &self.scene.name)
            .field("frame", &self.frame)
            .finish()
    }
}

impl VolumeSimulation {
    pub fn new(scene: VolumeScene, base_dir: Option<&std::path::Path>) -> Result<Self> {
        scene.validate()?;
        let mesh = scene.build_mesh(base_dir)?;
        let nv = mesh.num_vertices();
        let x0 = mesh.flat_positions();
        let lame = LameParameters::from_young_poisson(scene.young, scene.poisson)?;
        let elastic = TetElasticity::new(&mesh, scene.material, lame)?;
        let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), scene.density);
        let anchor_nodes = match &scene.anchors {
            AnchorSpec::Min { axis, tolerance } => anchors::nodes_at_min(mesh.positions(), *axis, *tolerance)?,
            AnchorSpec::Plane {
                point,
                normal,
                tolerance,
            } => anchors::nodes_on_plane(mesh.positions(), *point, *normal, *tolerance)?,
            AnchorSpec::Indices { indices } => indices.clone(),
        };
        if anchor_nodes.is_empty() {
            return Err(Error::Scene("the anchor specification selects no node".into()));
        }
        let fixed = anchors::fixed_dofs(nv, &anchor_nodes)?;
        let mut forces = vec![0.0; 3 * nv];
        let mut add = |f: ConstantForce| forces.iter_mut().zip(f.forces()).for_each(|(a, b)| *a += b);
        if let Some(g) = scene.gravity {
            add(ConstantForce::gravity(&masses, g)?);
        }
        match &scene.force_field {
            Some(ForceField::Directional {
                direction,
                acceleration,
            }) => add(ConstantForce::directional(&masses, *direction, *acceleration)?),
            Some(ForceField::Circular {
                center,
                axis,
                acceleration,
            }) => add(ConstantForce::circular(&masses, &x0, *center, *axis, *acceleration)?),
            None => {}
        }
        let load = || ConstantForce::new("external load", forces.clone());
        let solver = match scene.solve {
            VolumeSolve::ImplicitEuler { dt } => {
                let terms: Vec<Box<dyn Energy>> = vec![Box::new(elastic), Box::new(load()?)];
                Solver::Euler(ImplicitEuler::new(masses, dt, x0, terms, fixed)?)
            }
            VolumeSolve::Newmark {
                dt,
                rayleigh_mass,
                rayleigh_stiffness,
            } => {
                let terms: Vec<Box<dyn Energy>> = vec![Box::new(elastic), Box::new(load()?)];
                let damping = RayleighDamping {
                    mass: rayleigh_mass,
                    stiffness: rayleigh_stiffness,
                };
                Solver::Newmark(Newmark::new(
                    masses,
                    dt,
                    x0.clone(),
                    vec![0.0; x0.len()],
                    terms,
                    fixed,
                    damping,
                )?)
            }
            VolumeSolve::Quasistatic => {
                let solver = Quasistatic::new(x0.len(), &[&elastic], fixed)?;
                Solver::Quasistatic { solver, elastic, x: x0 }
            }
            VolumeSolve::StaticLinear => Solver::Linear(PrefactorizedLinear::new(
                &x0,
                &[&elastic],
                masses,
                fixed,
                LinearSolve::Static,
            )?),
            VolumeSolve::DynamicLinear {
                dt,
                rayleigh_mass,
                rayleigh_stiffness,
            } => {
                let damping = RayleighDamping {
                    mass: rayleigh_mass,
                    stiffness: rayleigh_stiffness,
                };
                let mode = LinearSolve::Dynamic { dt, damping };
                Solver::Linear(PrefactorizedLinear::new(&x0, &[&elastic], masses, fixed, mode)?)
            }
        };
        Ok(Self {
            scene,
            mesh,
            anchors: anchor_nodes,
            forces,
            solver,
            frame: 0,
        })
    }

    pub fn scene(&self) -> &VolumeScene {
        &self.scene
    }
    pub fn mesh(&self) -> &TetMesh {
        &self.mesh
    }
    pub fn anchors(&self) -> &[usize] {
        &self.anchors
    }
    /// The external load: gravity plus the scene's force field, as nodal forces (N, flat).
    pub fn external_forces(&self) -> &[f64] {
        &self.forces
    }
    pub fn frame_index(&self) -> usize {
        self.frame
    }
    /// Current node positions (flat, m).
    pub fn positions(&self) -> Vec<f64> {
        match &self.solver {
            Solver::Euler(ie) => ie.positions().to_vec(),
            Solver::Newmark(nm) => nm.positions().to_vec(),
            Solver::Quasistatic { x, .. } => x.clone(),
            Solver::Linear(lin) => lin.positions(),
        }
    }
    /// The Newton settings of the dynamic solves (implicit Euler, Newmark); `None` for
    /// the quasistatic and linear solves. Evaluations tighten them for a reference run.
    pub fn newton_settings_mut(&mut self) -> Option<&mut crate::NewtonSettings> {
        match &mut self.solver {
            Solver::Euler(ie) => Some(&mut ie.settings),
            Solver::Newmark(nm) => Some(&mut nm.settings),
            _ => None,
        }
    }

    /// Advances one frame (a time step, or the next load increment).
    pub fn step(&mut self) -> Result<VolumeFrame> {
        let m = self.frame + 1;
        let fraction = m as f64 / self.scene.frames as f64;
        let hold: Vec<(usize, f64)> = Vec::new();
        let frame = match &mut self.solver {
            Solver::Euler(ie) => {
                let r = ie.step(&hold)?;
                VolumeFrame {
                    positions: ie.positions().to_vec(),
                    iterations: r.newton.iterations,
                    residual: r.newton.residual,
                    seconds: r.seconds,
                }
            }
            Solver::Newmark(nm) => {
                let r = nm.step(&hold)?;
                VolumeFrame {
                    positions: nm.positions().to_vec(),
                    iterations: r.newton.iterations,
                    residual: r.newton.residual,
                    seconds: r.seconds,
                }
            }
            Solver::Quasistatic { solver, elastic, x } => {
                let load: Vec<f64> = self.forces.iter().map(|f| f * fraction).collect();
                let r = solver.solve(&[&*elastic], &load, x, 1)?;
                VolumeFrame {
                    positions: x.clone(),
                    iterations: r.newton.iter().map(|n| n.iterations).sum(),
                    residual: r.newton.last().map_or(0.0, |n| n.residual),
                    seconds: r.seconds,
                }
            }
            Solver::Linear(lin) => {
                let forces: Vec<f64> = match lin.mode() {
                    LinearSolve::Static => self.forces.iter().map(|f| f * fraction).collect(),
                    LinearSolve::Dynamic { .. } => self.forces.clone(),
                };
                let r = lin.step(&forces, &hold)?;
                VolumeFrame {
                    positions: lin.positions(),
                    iterations: 0,
                    residual: 0.0,
                    seconds: r.seconds,
                }
            }
        };
        if let Some(i) = frame.positions.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "simulated position",
                dof: i,
            });
        }
        self.frame = m;
        Ok(frame)
    }
}

/// Surface resolutions of the limb body.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LimbResolution {
    /// About 1.2 k tets: tests.
    Quick,
    /// About 15 k tets, 1410 surface vertices.
    Default,
    /// 6890 surface vertices (the SMPL body's count): speed measurements.
    Smpl,
    /// About 50 k tets: the FEM benchmark size.
    Benchmark,
}

impl LimbResolution {
    pub fn params(self) -> LimbParams {
        match self {
            Self::Quick => LimbParams::quick(),
            Self::Default => LimbParams::default(),
            Self::Smpl => LimbParams::smpl_resolution(),
            Self::Benchmark => LimbParams::benchmark(),
        }
    }
}

/// The `limb` soft-tissue scene (design §6): skinned surface `X_t` and simulated
/// Neo-Hookean surface `Y_t` per frame, in vertex correspondence, metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SoftTissueScene {
    #[serde(rename = "type")]
    pub tag: SoftTissueTag,
    pub name: String,
    pub resolution: LimbResolution,
    pub params: SoftTissueParams,
    pub frames: usize,
}

impl SoftTissueScene {
    pub fn builtin(quick: bool) -> Self {
        Self {
            tag: SoftTissueTag::SoftTissue,
            name: "limb".into(),
            resolution: if quick {
                LimbResolution::Quick
            } else {
                LimbResolution::Default
            },
            params: SoftTissueParams::default(),
            frames: if quick { 10 } else { 300 },
        }
    }
    pub fn from_toml(text: &str) -> Result<Self> {
        let s: Self = toml::from_str(text).map_err(|e| Error::Scene(format!("invalid soft-tissue scene TOML: {e}")))?;
        if s.frames == 0 {
            return Err(Error::Scene("frames must be at least 1".into()));
        }
        Ok(s)
    }
    pub fn to_toml(&self) -> Result<String> {
        toml::to_string_pretty(self).map_err(|e| Error::Scene(format!("cannot serialise scene: {e}")))
    }
    /// The built-in soft-tissue scene `name` (`limb` or `limb-jiggle`; anything else is
    /// `limb`).
    pub fn builtin_named(name: &str, quick: bool) -> Self {
        let mut scene = Self::builtin(quick);
        if name == JIGGLE_SCENE {
            scene.name = name.into();
            scene.params = SoftTissueParams::jiggle();
        }
        scene
    }

    /// The runnable simulation.
    pub fn build(&self) -> Result<SoftTissue> {
        SoftTissue::new(weft_mesh::limb::limb(&self.resolution.params())?, self.params)
    }
}
