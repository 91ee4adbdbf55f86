//! Experiment `nnwarp`: NNWarp (Luo et al.) against full nonlinear FEM, beside modal
//! warping, rotation-strain warping and plain linear FEM, per shape and material.
//!
//! The `nnwarp` dataset is generated and one network per material trained into
//! `OUT/nnwarp/` (both resumed). Each shape is clamped (beams at their −x end, the limb at
//! its bones) and loaded by one directional field the networks never saw, at loads whose
//! static linear answer moves some node by 0.5, 1 and 1.5 in unit-sphere units (the
//! training range ends at 2). At each load the warps correct the stiffness-warped static
//! linear solution (the load rotated into each node's rest frame, iterated to its fixed
//! point) and `linear` is the plain one; the reference is the material's static nonlinear
//! equilibrium under the same load, continued from the previous one. `rel-error` is
//! averaged over the loads. Beside the records: error against load past the trained range
//! and against field direction (NNWarp Figs. 18–19), and the beam tip's trajectory at two
//! time steps (Fig. 15).

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use crate::error::Context;
use nalgebra::Vector3;
use weft_mesh::TetMesh;
use weft_mesh::generators::{BeamParams, beam, bent_beam, t_beam, tapered_beam};
use weft_nn::nnwarp::{NnWarp, NnWarpSimulation, WarpContext, WarpTrainingSettings, load_model, rel_error};
use weft_sim::energies::{LameParameters, Material, TetElasticity};
use weft_sim::scenes::volume::LimbResolution;
use weft_sim::warp::{
    FieldDirection, NodalGradients, RotationStrainWarp, modal_warp, unit_sphere_normalization, warped_static_solve,
};
use weft_sim::{LinearSolve, PrefactorizedLinear, Quasistatic};

use super::context::EvalContext;
use crate::records::{ExperimentOutput, LinePlot, Series, Timing};
use weft_data::Size;

/// Linear answers' largest displacement at the evaluated loads (unit-sphere units).
const LEVELS: [f64; 3] = [0.5, 1.0, 1.5];
/// The evaluation field: `hemisphere_direction(α = 1.2, β = 0.6)`, inside the trained
/// octant but drawn by no training sequence's seed.
const FIELD_ANGLES: (f64, f64) = (1.2, 0.6);
/// The warped linear solve's fixed point: relative change between solves, and the most
/// solves allowed.
const WARP_TOLERANCE: f64 = 1e-4;
const WARP_SOLVES: usize = 100;
/// Newton load increments of the nonlinear reference from one load to the next.
const REFERENCE_STEPS: usize = 4;
/// Newton iterations per increment, and halvings of an increment, before the reference
/// gives up on a load (reported under failures).
const REFERENCE_NEWTON_ITERATIONS: usize = 50;
const REFERENCE_SUBDIVISIONS: usize = 3;
/// The time steps of the trajectory figure (NNWarp Fig. 15 shows two).
const TRAJECTORY_STEPS: [f64; 2] = [0.01, 0.04];
const YOUNG: f64 = 1e5;
const POISSON: f64 = 0.3;
const DENSITY: f64 = 1000.0;

struct Shape {
    name: &'static str,
    mesh: TetMesh,
    anchors: Vec<usize>,
    split: &'static str,
}

fn min_x_anchors(mesh: &TetMesh) -> Vec<usize> {
    let x_min = mesh.positions().iter().map(|p| p.x).fold(f64::INFINITY, f64::min);
    (0..mesh.num_vertices())
        .filter(|&i| (mesh.positions()[i].x - x_min).abs() < 1e-9)
        .collect()
}

/// The training beam, three unseen beams and the limb body (15 k tets at standard size).
fn shapes(size: Size) -> crate::Result<Vec<Shape>> {
    let quick = size == Size::Quick;
    let params = BeamParams {
        cells: if quick { [6, 3, 3] } else { [12, 6, 6] },
        size: [1.0, 0.5, 0.5],
    };
    let mut out = Vec::new();
    for (name, mesh, split) in [
        ("beam", beam(&params)?, "train-shape"),
        ("tapered-beam", tapered_beam(&params, 0.5)?, "unseen-shape"),
        ("bent-beam", bent_beam(&params, 0.6)?, "unseen-shape"),
        ("t-beam", t_beam(&params)?, "unseen-shape"),
    ] {
        let anchors = min_x_anchors(&mesh);
        out.push(Shape {
            name,
            mesh,
            anchors,
            split,
        });
    }
    // The error rows' limb is the 15 k-tet one: a Newton reference of the 50 k-tet limb
    // took over 9 minutes for its first load alone (co-rotational; assembly and
    // factorisation of the projected Hessian, about a second per iteration), so the
    // nine loads would take hours. The 50 k-tet body is timed in NNWarp Table 1 (`run`).
    out.push(limb(if quick {
        LimbResolution::Quick
    } else {
        LimbResolution::Default
    })?);
    Ok(out)
}

/// The `limb` body at `resolution`, clamped at its bones.
fn limb(resolution: LimbResolution) -> crate::Result<Shape> {
    let limb = weft_mesh::limb::limb(&resolution.params())?;
    Ok(Shape {
        name: "limb",
        anchors: limb.all_bone_nodes(),
        mesh: limb.mesh,
        split: "unseen-shape",
    })
}

fn training_config(size: Size) -> WarpTrainingSettings {
    let mut c = WarpTrainingSettings::default();
    if size == Size::Quick {
        c.batch = 256;
        c.epochs = 40;
    }
    c
}

fn material_of(m: WarpMaterial) -> Material {
    match m {
        WarpMaterial::CoRotational => Material::CoRotational,
        WarpMaterial::Stvk => Material::StVK,
        WarpMaterial::NeoHookean => Material::NeoHookean,
    }
}

/// The nonlinear materials an NNWarp network is trained for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WarpMaterial {
    CoRotational,
    Stvk,
    NeoHookean,
}

impl WarpMaterial {
    pub const ALL: [WarpMaterial; 3] = [Self::CoRotational, Self::Stvk, Self::NeoHookean];

    /// The dataset's array name.
    pub fn key(self) -> &'static str {
        match self {
            Self::CoRotational => "co-rotational",
            Self::Stvk => "stvk",
            Self::NeoHookean => "neo-hookean",
        }
    }
}

impl std::str::FromStr for WarpMaterial {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|m| m.key() == s)
            .ok_or_else(|| format!("{s:?} is not a material (co-rotational, stvk or neo-hookean)"))
    }
}

/// Per method: summed rel-error and seconds over the loads.
#[derive(Default, Clone, Copy)]
struct Tally {
    error: f64,
    seconds: f64,
}

/// The methods scored, in the records' order.
const METHODS: [&str; 4] = ["nnwarp", "modal-warping", "rotation-strain-warping", "linear"];

/// One shape prepared for one field direction: the pre-factorised linear system, the
/// warps' shared gradient fit, rotation-strain warping's factorised Poisson system, and
/// the unit load.
struct Bench<'a> {
    shape: &'a Shape,
    rest: Vec<f64>,
    fixed: Vec<bool>,
    /// The directional field at 1 m/s² (N, flat).
    unit_force: Vec<f64>,
    linear: PrefactorizedLinear,
    gradients: Arc<NodalGradients>,
    rsw: RotationStrainWarp,
    /// Unit-sphere scale of the shape (1/m).
    scale: f64,
    /// The largest node displacement of the linear answer to `unit_force` (m).
    reach: f64,
}

impl<'a> Bench<'a> {
    fn new(shape: &'a Shape, direction: Vector3<f64>, lame: LameParameters) -> crate::Result<Self> {
        crate::error::ensure!(!shape.anchors.is_empty(), "{} has no anchored node", shape.name);
        let mesh = &shape.mesh;
        let n = 3 * mesh.num_vertices();
        let rest = mesh.flat_positions();
        let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), DENSITY);
        let fixed = weft_sim::anchors::fixed_dofs(mesh.num_vertices(), &shape.anchors)?;
        let unit_force = weft_sim::energies::ConstantForce::directional(&masses, direction.into(), 1.0)?
            .forces()
            .to_vec();
        let linear_energy = TetElasticity::new(mesh, Material::Linear, lame)?;
        let mut linear =
            PrefactorizedLinear::new(&rest, &[&linear_energy], masses, fixed.clone(), LinearSolve::Static)?;
        let (_, scale) = unit_sphere_normalization(mesh.positions());
        linear.step(&unit_force, &[])?;
        let reach = max_node_displacement(linear.displacements());
        crate::error::ensure!(reach > 0.0, "{}: the field moves no node", shape.name);
        let gradients = Arc::new(NodalGradients::new(mesh)?);
        let mut anchored = vec![false; n / 3];
        shape.anchors.iter().for_each(|&i| anchored[i] = true);
        let rsw = RotationStrainWarp::new(mesh, gradients.clone(), anchored)?;
        Ok(Self {
            shape,
            rest,
            fixed,
            unit_force,
            linear,
            gradients,
            rsw,
            scale,
            reach,
        })
    }

    /// The load whose linear answer moves some node by `level` in unit-sphere units.
    fn load(&self, level: f64) -> Vec<f64> {
        let a = level / (self.reach * self.scale);
        self.unit_force.iter().map(|f| f * a).collect()
    }

    fn nnwarp(&self, model_dir: &Path, field: FieldDirection) -> crate::Result<NnWarp> {
        let (_, mlp) = load_model(model_dir)?;
        let context = WarpContext::with_gradients(
            &self.shape.mesh,
            self.gradients.clone(),
            &self.shape.anchors,
            field,
            POISSON,
            self.scale,
        )?;
        Ok(NnWarp::new(context, mlp))
    }

    /// Every method's `rel-error` at `level` against `reference`, advanced to that load.
    /// The warps correct the stiffness-warped linear answer `K ũ = 𝓡(ũ)ᵀ f`: NNWarp's
    /// runtime (§4) and modal warping (Choi & Ko) both see the load in each node's rest
    /// frame, and only then is the registration target `f_int(u) = 𝓡 K ũ` the equilibrium
    /// under `f` (docs/NNWARP.md). `linear` is the plain solve.
    /// `nnwarps` are one material's networks, one per seed: NNWarp's error is their mean,
    /// each kept in `Scored::nnwarp_seeds`.
    fn score(&mut self, nnwarps: &[NnWarp], reference: &mut Reference, level: f64) -> crate::Result<Scored> {
        let load = self.load(level);
        let truth = reference.advance(level, &load, &self.rest)?;
        let t = Instant::now();
        self.linear.step(&load, &[])?;
        let linear_seconds = t.elapsed().as_secs_f64();
        let u = self.linear.displacements().to_vec();
        let t = Instant::now();
        let report = warped_static_solve(&mut self.linear, &self.gradients, &load, WARP_TOLERANCE, WARP_SOLVES)?;
        let warped_seconds = t.elapsed().as_secs_f64();
        let uw = self.linear.displacements().to_vec();
        let mut errors = [0.0; 4];
        let mut seconds = [0.0; 4];
        let mut nnwarp_seeds = Vec::with_capacity(nnwarps.len());
        for other in nnwarps.iter().skip(1) {
            nnwarp_seeds.push(rel_error(&other.warp(&uw)?, &truth));
        }
        let first = nnwarps.first().context("no NNWarp network to score")?;
        for (k, name) in METHODS.iter().enumerate() {
            let t = Instant::now();
            let predicted = match *name {
                "nnwarp" => first.warp(&uw)?,
                "modal-warping" => modal_warp(&self.gradients, &uw)?,
                "rotation-strain-warping" => self.rsw.warp(&uw)?,
                _ => u.clone(),
            };
            let solve = if *name == "linear" {
                linear_seconds
            } else {
                warped_seconds
            };
            seconds[k] = solve + t.elapsed().as_secs_f64();
            errors[k] = rel_error(&predicted, &truth);
        }
        nnwarp_seeds.insert(0, errors[0]);
        errors[0] = nnwarp_seeds.iter().sum::<f64>() / nnwarp_seeds.len() as f64;
        Ok(Scored {
            errors,
            seconds,
            solves: report.solves,
            nnwarp_seeds,
        })
    }
}

/// One load's scores, in [`METHODS`] order.
struct Scored {
    /// NNWarp's is the mean over its seeds.
    errors: [f64; 4],
    seconds: [f64; 4],
    /// Linear solves the warped fixed point took.
    solves: usize,
    /// NNWarp's error per seed.
    nnwarp_seeds: Vec<f64>,
}

/// A material's static nonlinear equilibrium, continued from load to load, each one
/// cached on disk: the limb's take minutes, and an interrupted evaluation resumes from
/// them.
struct Reference {
    elastic: TetElasticity,
    quasistatic: Quasistatic,
    x: Vec<f64>,
    load: Option<Vec<f64>>,
    /// Wall time of every advance so far (a cached one counts its recorded time).
    seconds: f64,
    /// `OUT/nnwarp/references/<shape>/<material>/<field>`.
    cache: std::path::PathBuf,
}

impl Reference {
    /// `field` names the load's direction in the cache.
    fn new(root: &Path, bench: &Bench, m: WarpMaterial, lame: LameParameters, field: &str) -> crate::Result<Self> {
        let elastic = TetElasticity::new(&bench.shape.mesh, material_of(m), lame)?;
        let mut quasistatic = Quasistatic::new(bench.rest.len(), &[&elastic], bench.fixed.clone())?;
        // A load the material cannot follow (StVK's collapse, an inverted element) should
        // end its scene in minutes, not retry for an hour on the 50 k-tet limb: each
        // failed attempt costs up to `max_iterations` Newton steps of about a second.
        quasistatic.settings.max_iterations = REFERENCE_NEWTON_ITERATIONS;
        quasistatic.max_subdivisions = REFERENCE_SUBDIVISIONS;
        Ok(Self {
            elastic,
            quasistatic,
            x: bench.rest.clone(),
            load: None,
            seconds: 0.0,
            cache: root.join("references").join(bench.shape.name).join(m.key()).join(field),
        })
    }

    /// Moves to the equilibrium under `load` (the one whose linear answer reaches `level`)
    /// in `REFERENCE_STEPS` increments from the last one, or reads it from the cache, and
    /// returns its displacements from `rest`.
    fn advance(&mut self, level: f64, load: &[f64], rest: &[f64]) -> crate::Result<Vec<f64>> {
        let path = self.cache.join(format!("level-{level:.4}.safetensors"));
        if let Some((x, seconds)) = read_reference(&path, self.x.len()) {
            self.x = x;
            self.seconds += seconds;
        } else {
            let t = Instant::now();
            self.quasistatic
                .solve_from(
                    &[&self.elastic],
                    self.load.as_deref(),
                    load,
                    &mut self.x,
                    REFERENCE_STEPS,
                )
                .context("nonlinear reference")?;
            let seconds = t.elapsed().as_secs_f64();
            self.seconds += seconds;
            std::fs::create_dir_all(&self.cache)?;
            weft_data::files::write_safetensors(
                &path,
                &[weft_data::files::Array::f64("positions", vec![self.x.len()], &self.x)],
                [("seconds".to_string(), seconds.to_string())].into(),
            )?;
        }
        self.load = Some(load.to_vec());
        Ok(self.x.iter().zip(rest).map(|(x, r)| x - r).collect())
    }
}

/// A cached equilibrium of `len` DOFs and the seconds it took; `None` if absent or not
/// readable as one (then it is recomputed and overwritten).
fn read_reference(path: &Path, len: usize) -> Option<(Vec<f64>, f64)> {
    let bytes = std::fs::read(path).ok()?;
    let (_, header) = safetensors::SafeTensors::read_metadata(&bytes).ok()?;
    let seconds = header.metadata().as_ref()?.get("seconds")?.parse().ok()?;
    let st = safetensors::SafeTensors::deserialize(&bytes).ok()?;
    let t = st.tensor("positions").ok()?;
    if t.dtype() != safetensors::Dtype::F64 || t.shape() != [len] {
        return None;
    }
    let x: Vec<f64> = t
        .data()
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
        .collect();
    x.iter().all(|v| v.is_finite()).then_some((x, seconds))
}

/// The cache name of the field `hemisphere_direction(alpha, FIELD_ANGLES.1)`.
fn field_tag(alpha: f64) -> String {
    format!("E{YOUNG}-nu{POISSON}-alpha-{alpha:.3}-beta-{:.3}", FIELD_ANGLES.1)
}

/// The largest node displacement of flat displacements `u`.
fn max_node_displacement(u: &[f64]) -> f64 {
    u.chunks_exact(3)
        .map(|c| Vector3::new(c[0], c[1], c[2]).norm())
        .fold(0.0, f64::max)
}

/// One empty line per method, in [`METHODS`] order.
fn method_series() -> Vec<Series> {
    METHODS
        .iter()
        .map(|m| Series {
            label: m.to_string(),
            x: Vec::new(),
            y: Vec::new(),
        })
        .collect()
}

/// Adds every method's error at `x`.
fn push_point(series: &mut [Series], x: f64, scored: &Scored) {
    for (s, e) in series.iter_mut().zip(scored.errors) {
        s.x.push(x);
        s.y.push(e);
    }
}

/// NNWarp Fig. 18: `rel-error` of every method as the load grows past the trained range
/// (which ends where the linear answer moves a node by 2), Neo-Hookean.
fn load_extrapolation(
    root: &Path,
    model: &Path,
    shape: &Shape,
    direction: Vector3<f64>,
    field: FieldDirection,
    lame: LameParameters,
    size: Size,
) -> crate::Result<LinePlot> {
    let mut bench = Bench::new(shape, direction, lame)?;
    let nnwarp = [bench.nnwarp(model, field)?];
    let mut reference = Reference::new(root, &bench, WarpMaterial::NeoHookean, lame, &field_tag(FIELD_ANGLES.0))?;
    let levels: Vec<f64> = if size == Size::Quick {
        vec![0.5, 1.5, 2.5]
    } else {
        (1..=12).map(|k| 0.25 * k as f64).collect()
    };
    let mut series = method_series();
    for level in levels {
        // Past the reach of the nonlinear reference the curve ends.
        let Ok(scored) = bench.score(&nnwarp, &mut reference, level) else {
            break;
        };
        push_point(&mut series, level, &scored);
    }
    crate::error::ensure!(!series[0].x.is_empty(), "no load could be scored");
    Ok(LinePlot {
        name: format!("extrapolation-load-{}", shape.name),
        title: format!(
            "nnwarp / {}/neo-hookean: error as the load leaves the trained range (ends at 2)",
            shape.name
        ),
        x_label: "largest linear node displacement (unit-sphere units)".into(),
        y_label: "rel-error".into(),
        log_y: true,
        series,
    })
}

/// NNWarp Fig. 19: `rel-error` as the field's azimuth α leaves the trained quarter
/// hemisphere (α ∈ [0, π/2]; β fixed), at the middle load, Neo-Hookean. Each direction is
/// a fresh body: its contextual features and its reference depend on the field.
fn direction_extrapolation(
    root: &Path,
    model: &Path,
    shape: &Shape,
    lame: LameParameters,
    size: Size,
) -> crate::Result<LinePlot> {
    let alphas: Vec<f64> = if size == Size::Quick {
        vec![0.4, 1.2, 2.4]
    } else {
        (0..8).map(|k| 0.4 * k as f64).collect()
    };
    let mut series = method_series();
    for alpha in alphas {
        let direction = Vector3::from(weft_sim::energies::hemisphere_direction(alpha, FIELD_ANGLES.1));
        let mut bench = Bench::new(shape, direction, lame)?;
        let nnwarp = [bench.nnwarp(model, FieldDirection::Directional(direction))?];
        let mut reference = Reference::new(root, &bench, WarpMaterial::NeoHookean, lame, &field_tag(alpha))?;
        let Ok(scored) = bench.score(&nnwarp, &mut reference, 1.0) else {
            continue;
        };
        push_point(&mut series, alpha, &scored);
    }
    crate::error::ensure!(!series[0].x.is_empty(), "no direction could be scored");
    Ok(LinePlot {
        name: format!("extrapolation-direction-{}", shape.name),
        title: format!(
            "nnwarp / {}/neo-hookean: error as the field's azimuth α leaves [0, π/2] (β = {})",
            shape.name, FIELD_ANGLES.1
        ),
        x_label: "field azimuth α (rad)".into(),
        y_label: "rel-error".into(),
        log_y: true,
        series,
    })
}

/// NNWarp Fig. 15: the beam's tip node over time under a suddenly applied field, full
/// Neo-Hookean implicit Euler against NNWarp's runtime and linear FEM at time step `dt`.
/// Returns the plot and a note with each method's mean `rel-error` over the frames.
fn trajectory(model: &Path, direction: Vector3<f64>, dt: f64, size: Size) -> crate::Result<(LinePlot, String)> {
    use weft_sim::scenes::volume::{ForceField, VolumeSolve};
    let quick = size == Size::Quick;
    let mut scene = weft_sim::VolumeScene::builtin("beam-neo-hookean-field", quick)?;
    scene.young = YOUNG;
    scene.poisson = POISSON;
    scene.density = DENSITY;
    scene.solve = VolumeSolve::ImplicitEuler { dt };
    scene.frames = ((if quick { 0.3 } else { 1.5 }) / dt).round() as usize;
    // The field's strength: the static linear answer at the middle load.
    let probe = weft_sim::VolumeSimulation::new(scene.clone(), None)?;
    let shape = Shape {
        name: "beam",
        mesh: probe.mesh().clone(),
        anchors: probe.anchors().to_vec(),
        split: "train-shape",
    };
    let lame = LameParameters::from_young_poisson(YOUNG, POISSON)?;
    let bench = Bench::new(&shape, direction, lame)?;
    let acceleration = 1.0 / (bench.reach * bench.scale);
    scene.gravity = None;
    scene.force_field = Some(ForceField::Directional {
        direction: direction.into(),
        acceleration,
    });
    let mut full = weft_sim::VolumeSimulation::new(scene.clone(), None)?;
    let mut linear_scene = scene.clone();
    linear_scene.material = Material::Linear;
    let mut linear = weft_sim::VolumeSimulation::new(linear_scene, None)?;
    let (_, mlp) = load_model(model)?;
    let mut runtime = NnWarpSimulation::new(&full, mlp)?;
    // The tip node nearest the tip face's centre.
    let mesh = full.mesh();
    let x_max = mesh.positions().iter().map(|p| p.x).fold(f64::MIN, f64::max);
    let centre = mesh
        .positions()
        .iter()
        .filter(|p| (p.x - x_max).abs() < 1e-9)
        .fold(Vector3::zeros(), |a, p| a + p)
        / mesh
            .positions()
            .iter()
            .filter(|p| (p.x - x_max).abs() < 1e-9)
            .count()
            .max(1) as f64;
    let tip = (0..mesh.num_vertices())
        .min_by(|&a, &b| {
            (mesh.positions()[a] - centre)
                .norm()
                .total_cmp(&(mesh.positions()[b] - centre).norm())
        })
        .context("empty mesh")?;
    let rest = mesh.flat_positions();
    let along = |u: &[f64]| Vector3::new(u[3 * tip], u[3 * tip + 1], u[3 * tip + 2]).dot(&direction);
    let labels = ["full FEM (neo-hookean)", "nnwarp", "linear"];
    let mut series: Vec<Series> = labels
        .iter()
        .map(|l| Series {
            label: l.to_string(),
            x: vec![0.0],
            y: vec![0.0],
        })
        .collect();
    let (mut e_nnwarp, mut e_linear) = (0.0, 0.0);
    for k in 1..=scene.frames {
        let truth: Vec<f64> = full.step()?.positions.iter().zip(&rest).map(|(x, r)| x - r).collect();
        let lin: Vec<f64> = linear.step()?.positions.iter().zip(&rest).map(|(x, r)| x - r).collect();
        let warped = runtime.step()?.warped;
        e_nnwarp += rel_error(&warped, &truth);
        e_linear += rel_error(&lin, &truth);
        for (s, u) in series.iter_mut().zip([&truth, &warped, &lin]) {
            s.x.push(k as f64 * dt);
            s.y.push(along(u));
        }
    }
    let frames = scene.frames.max(1) as f64;
    let note = format!(
        "nnwarp/trajectory at Δt = {dt} s: beam tip node {tip}, {} frames under a field of {acceleration:.3} m/s² \
         applied at t = 0 (static linear answer 1 unit-sphere unit); mean rel-error over the frames: nnwarp {:.4}, \
         linear {:.4}",
        scene.frames,
        e_nnwarp / frames,
        e_linear / frames
    );
    Ok((
        LinePlot {
            name: format!("trajectory-dt-{}ms", (dt * 1e3).round()),
            title: format!("nnwarp / beam: tip node along the field over time, Δt = {dt} s"),
            x_label: "time (s)".into(),
            y_label: "tip displacement along the field (m)".into(),
            log_y: false,
            series,
        },
        note,
    ))
}

/// NNWarp Table 1's columns for one body, all measured here: tets, factorisation, one
/// static solve, the Neo-Hookean network's correction (means over `REPEATS`), frames per
/// second of the two together, and one full Neo-Hookean implicit-Euler frame (Δt = 0.01 s).
fn timing_row(
    out: &mut ExperimentOutput,
    shape: &Shape,
    model: &std::path::Path,
    lame: LameParameters,
) -> crate::Result<Vec<String>> {
    const REPEATS: usize = 20;
    let mesh = &shape.mesh;
    let rest = mesh.flat_positions();
    let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), DENSITY);
    let fixed = weft_sim::anchors::fixed_dofs(mesh.num_vertices(), &shape.anchors)?;
    let gravity = weft_sim::energies::ConstantForce::gravity(&masses, [0.0, -9.81, 0.0])?;
    let forces = gravity.forces().to_vec();
    let linear_energy = TetElasticity::new(mesh, Material::Linear, lame)?;
    let mut linear = PrefactorizedLinear::new(
        &rest,
        &[&linear_energy],
        masses.clone(),
        fixed.clone(),
        LinearSolve::Static,
    )?;
    let (_, mlp) = load_model(model)?;
    let context = WarpContext::new(
        mesh,
        &shape.anchors,
        FieldDirection::Directional(-Vector3::y()),
        POISSON,
    )?;
    let nnwarp = NnWarp::new(context, mlp);
    let (mut solve, mut correction) = (0.0, 0.0);
    for _ in 0..REPEATS {
        let t = Instant::now();
        linear.step(&forces, &[])?;
        solve += t.elapsed().as_secs_f64();
        let t = Instant::now();
        std::hint::black_box(nnwarp.warp(linear.displacements())?);
        correction += t.elapsed().as_secs_f64();
    }
    let (solve, correction) = (solve / REPEATS as f64, correction / REPEATS as f64);
    let terms: Vec<Box<dyn weft_sim::Energy>> = vec![
        Box::new(TetElasticity::new(mesh, Material::NeoHookean, lame)?),
        Box::new(gravity),
    ];
    let mut full = weft_sim::ImplicitEuler::new(masses, 0.01, rest, terms, fixed)?;
    let t = Instant::now();
    full.step(&[])?;
    let full_seconds = t.elapsed().as_secs_f64();
    let timing = Timing::new(solve + correction, full_seconds);
    for (metric, value, unit) in [
        ("correction-seconds", correction, "s"),
        ("fps", 1.0 / (solve + correction), "1/s"),
    ] {
        out.record(
            &format!("{}/neo-hookean", shape.name),
            "nnwarp",
            metric,
            value,
            unit,
            timing,
        );
        if let Some(r) = out.records.last_mut() {
            r.split = Some(shape.split.into());
        }
    }
    Ok(vec![
        format!("`{}`", shape.name),
        mesh.num_tets().to_string(),
        crate::paper::format_ms(linear.factorization_seconds()),
        crate::paper::format_ms(solve),
        crate::paper::format_ms(correction),
        format!("{:.0}", 1.0 / (solve + correction)),
        crate::paper::format_ms(full_seconds),
    ])
}

/// Training sequences of the data-size study (NNWarp trains on 520): sizes at or beyond
/// the dataset's training count are dropped and that count itself is always the last.
const DATA_SIZES: [usize; 4] = [64, 128, 256, 520];

/// Seeds per material: one at quick size (CI), three otherwise (the claims need three).
fn seeds(size: Size) -> Vec<u64> {
    match size {
        Size::Quick => vec![0],
        _ => vec![0, 1, 2],
    }
}

/// One network of the data-size study.
struct StudyRun {
    sequences: usize,
    seed: u64,
    /// The kept weights' correction error on the validation pairs
    /// ([`weft_nn::nnwarp::correction_rms`], unit-sphere units).
    validation_rms: f64,
    /// The epoch whose weights were kept.
    best_epoch: usize,
}

/// One material's networks: every (training sequences, seed) run's best validation score,
/// the seeds' final models (the largest size) and the one of them the validation split
/// selects.
struct Study {
    material: WarpMaterial,
    runs: Vec<StudyRun>,
    finals: Vec<std::path::PathBuf>,
    selected: std::path::PathBuf,
}

/// Trains material `m` on growing prefixes of the training sequences, each with every
/// seed, into `models/<material>/n<k>-seed<s>/` (resumed); selection reads the validation
/// split only.
fn data_size_study(
    ctx: &EvalContext,
    root: &Path,
    data: &Path,
    m: WarpMaterial,
    config: &WarpTrainingSettings,
    seeds: &[u64],
) -> crate::Result<Study> {
    let full = weft_data::WarpDataset::load(data, m.key())?;
    let available = full.training_count();
    let (val_x, val_y) = weft_nn::nnwarp::collect_pairs(&full, "validation")?;
    let mut sizes: Vec<usize> = DATA_SIZES.iter().copied().filter(|&k| k < available).collect();
    sizes.push(available);
    let mut runs = Vec::new();
    let mut finals = Vec::new();
    for &k in &sizes {
        let subset = full.with_training_prefix(k);
        for &seed in seeds {
            let dir = root.join("models").join(m.key()).join(format!("n{k}-seed{seed}"));
            let config = WarpTrainingSettings { seed, ..config.clone() };
            let label = format!("nnwarp/{}/n{k}-seed{seed}", m.key());
            let mut progress = crate::progress::TrainProgress::new(ctx.quiet, &label)?;
            let (state, _, _) = weft_nn::nnwarp::train_model(&dir, &subset, &config, &mut progress)
                .with_context(|| format!("training {label}"))?;
            let (_, mlp) = weft_nn::nnwarp::load_model(&dir)?;
            runs.push(StudyRun {
                sequences: k,
                seed,
                validation_rms: weft_nn::nnwarp::correction_rms(&mlp, &val_x, &val_y)?,
                best_epoch: state.best_epoch,
            });
            if k == available {
                finals.push(dir);
            }
        }
    }
    let best = runs
        .iter()
        .filter(|r| r.sequences == available)
        .enumerate()
        .min_by(|a, b| a.1.validation_rms.total_cmp(&b.1.validation_rms))
        .map(|(i, _)| i)
        .context("no trained model")?;
    Ok(Study {
        material: m,
        runs,
        selected: finals[best].clone(),
        finals,
    })
}

/// The data-size study's learning curve (validation only) and table.
fn study_report(out: &mut ExperimentOutput, studies: &[Study], seeds: &[u64]) {
    let mut rows = Vec::new();
    let mut series = Vec::new();
    for study in studies {
        let mut sizes: Vec<usize> = study.runs.iter().map(|r| r.sequences).collect();
        sizes.dedup();
        let mut x = Vec::new();
        let mut y = Vec::new();
        for &k in &sizes {
            let at: Vec<&StudyRun> = study.runs.iter().filter(|r| r.sequences == k).collect();
            let (mean, sd) = crate::records::mean_sd(at.iter().map(|r| r.validation_rms));
            x.push(k as f64);
            y.push(mean);
            rows.push(vec![
                study.material.key().to_string(),
                k.to_string(),
                format!("{mean:.4e} ± {sd:.1e}"),
                at.iter()
                    .map(|r| format!("{} (seed {})", r.best_epoch, r.seed))
                    .collect::<Vec<_>>()
                    .join(", "),
            ]);
        }
        series.push(Series {
            label: study.material.key().to_string(),
            x,
            y,
        });
        let selected = study
            .selected
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned());
        out.notes.push(format!(
            "nnwarp/{}: selected on validation for the figures: `{selected}`",
            study.material.key()
        ));
    }
    out.tables.push(crate::paper::Table {
        title: "NNWarp — validation error against training data (data-size study)".into(),
        caption: format!(
            "Root-mean-square error of the runtime correction on every validation pair (unit-sphere units, mean ± sd \
             over {} seed(s); one scale for every run, unlike the trainer's standardised score) of each \
             material's network trained on the first k training sequences of the `nnwarp` dataset, and the epoch \
             each seed kept. The validation split only: the test shapes are scored once, with the largest k.",
            seeds.len()
        ),
        header: ["material", "training sequences", "validation RMS", "kept epochs"]
            .map(String::from)
            .to_vec(),
        rows,
    });
    out.lines.push(LinePlot {
        name: "data-size".into(),
        title: "NNWarp: validation error against training sequences".into(),
        x_label: "training sequences".into(),
        y_label: "validation correction RMS (unit-sphere units, mean over seeds)".into(),
        log_y: true,
        series,
    });
}

pub fn run(ctx: &EvalContext) -> crate::Result<ExperimentOutput> {
    let mut out = ExperimentOutput::new("nnwarp", ctx.size);
    let root = ctx.out.join("nnwarp");
    let data = root.join("data");
    let stopped = super::context::generate_dataset(ctx, weft_data::nnwarp::NAME, &data).context("nnwarp dataset")?;
    out.failures.extend(stopped);
    let config = training_config(ctx.size);
    std::fs::create_dir_all(&root)?;
    let config_path = root.join("config.json");
    std::fs::write(&config_path, serde_json::to_string_pretty(&config)?)?;
    let materials = [WarpMaterial::CoRotational, WarpMaterial::Stvk, WarpMaterial::NeoHookean];
    let seeds = seeds(ctx.size);
    out.seeds = seeds.len();
    let mut studies = Vec::new();
    for m in materials {
        let study = data_size_study(ctx, &root, &data, m, &config, &seeds)?;
        studies.push(study);
    }
    study_report(&mut out, &studies, &seeds);
    let selected = |m: WarpMaterial| -> crate::Result<&Path> {
        studies
            .iter()
            .find(|s| s.material == m)
            .map(|s| s.selected.as_path())
            .context("a material without a trained model")
    };
    let direction = Vector3::from(weft_sim::energies::hemisphere_direction(FIELD_ANGLES.0, FIELD_ANGLES.1));
    let field = FieldDirection::Directional(direction);
    out.notes.push(format!(
        "nnwarp: networks of {:?} epochs, batch {}, on the `nnwarp` dataset ({} size), {} seeds per material (NNWarp's \
         rel-error is their mean, `rel-error-sd` their spread; the other figures use each material's seed with the \
         best validation score); evaluation field along \
         ({:.3}, {:.3}, {:.3}), loads whose linear answer moves a node by {:?} in unit-sphere units, E = {YOUNG} Pa, \
         ν = {POISSON}; reference: static nonlinear equilibrium by load stepping",
        config.epochs,
        config.batch,
        ctx.size.as_str(),
        seeds.len(),
        direction.x,
        direction.y,
        direction.z,
        LEVELS
    ));
    let lame = LameParameters::from_young_poisson(YOUNG, POISSON)?;
    let shapes = shapes(ctx.size)?;
    let mut timing_rows = Vec::new();
    // NNWarp Table 1's bodies: the training beam and the ~50 k-tet limb (quick: the
    // quick limb).
    let timed_limb = limb(if ctx.size == Size::Quick {
        LimbResolution::Quick
    } else {
        LimbResolution::Benchmark
    })?;
    for shape in shapes.iter().filter(|s| s.name == "beam").chain([&timed_limb]) {
        timing_rows.push(timing_row(&mut out, shape, selected(WarpMaterial::NeoHookean)?, lame)?);
    }
    out.tables.push(crate::paper::Table {
        title: "NNWarp (Luo et al.) Table 1 — time performance, ours (paper beside)".into(),
        caption: "All columns measured in this run on this machine: pre-factorised linear FEM (factorisation, one \
                  static solve), the Neo-Hookean network's node-wise correction, frames per second of solve and \
                  correction together, and one full Neo-Hookean implicit-Euler frame (Δt = 0.01 s) on the same \
                  body. The paper (8-core i7, Eigen): beam 2,629 tets, 6.9 ms factorisation, < 1 ms solve, 333 \
                  FPS; dragon 51,850 tets, 307 ms, 15 ms, 15–18 FPS."
            .into(),
        header: [
            "body",
            "tetrahedra",
            "factorisation",
            "solve",
            "NNWarp correction",
            "FPS",
            "full Neo-Hookean frame",
        ]
        .map(String::from)
        .to_vec(),
        rows: timing_rows,
    });
    // Scenes, then the three figures' runs: load (two beams), direction, trajectories.
    let bar = weft_data::files::progress_bar(
        ctx.quiet,
        (shapes.len() * materials.len() + 3 + TRAJECTORY_STEPS.len()) as u64,
        "nnwarp",
        "runs",
    )?;
    for shape in &shapes {
        let mut bench = Bench::new(shape, direction, lame)?;
        for m in materials {
            let scene = format!("{}/{}", shape.name, m.key());
            bar.set_message(scene.clone());
            bar.inc(1);
            let finals = &studies
                .iter()
                .find(|s| s.material == m)
                .context("a material without a trained model")?
                .finals;
            let nnwarp = finals
                .iter()
                .map(|dir| bench.nnwarp(dir, field))
                .collect::<crate::Result<Vec<_>>>()?;
            let mut reference = Reference::new(&root, &bench, m, lame, &field_tag(FIELD_ANGLES.0))?;
            let mut tallies = [Tally::default(); 4];
            let mut seed_errors = vec![0.0; nnwarp.len()];
            let mut per_level = Vec::new();
            let mut solves = Vec::new();
            for level in LEVELS {
                // A load the reference or the warped solve cannot reach ends the scene's
                // loads (each continues from the last); the failure is reported, the loads
                // before it are scored.
                let scored = match bench.score(&nnwarp, &mut reference, level) {
                    Ok(s) => s,
                    Err(e) => {
                        out.failures.push(format!("nnwarp/{scene}: load {level}: {e:#}"));
                        break;
                    }
                };
                for (t, (e, sec)) in tallies.iter_mut().zip(scored.errors.iter().zip(&scored.seconds)) {
                    t.error += e;
                    t.seconds += sec;
                }
                for (sum, e) in seed_errors.iter_mut().zip(&scored.nnwarp_seeds) {
                    *sum += e;
                }
                solves.push(scored.solves);
                per_level.push((level, scored.errors));
            }
            if per_level.is_empty() {
                continue;
            }
            let levels = per_level.len() as f64;
            for (k, name) in METHODS.iter().enumerate() {
                out.record(
                    &scene,
                    name,
                    "rel-error",
                    tallies[k].error / levels,
                    "1",
                    Timing::new(tallies[k].seconds / levels, reference.seconds / levels),
                );
                if let Some(r) = out.records.last_mut() {
                    r.split = Some(shape.split.into());
                }
            }
            // NNWarp's spread over its seeds (each seed's error averaged over the loads).
            let per_seed: Vec<f64> = seed_errors.iter().map(|e| e / levels).collect();
            out.record(
                &scene,
                "nnwarp",
                "rel-error-sd",
                crate::records::mean_sd(per_seed.iter().copied()).1,
                "1",
                Timing::default(),
            );
            if let Some(r) = out.records.last_mut() {
                r.split = Some(shape.split.into());
            }
            out.notes.push(format!(
                "nnwarp/{scene}: {} nodes, {} tets, {} anchored; warped linear solves per load {:?}; rel-error per \
                 load (nnwarp, modal-warping, rotation-strain-warping, linear): {}",
                shape.mesh.num_vertices(),
                shape.mesh.num_tets(),
                shape.anchors.len(),
                solves,
                per_level
                    .iter()
                    .map(|(l, e)| format!(
                        "{l}: {}",
                        e.iter().map(|v| format!("{v:.4}")).collect::<Vec<_>>().join(" / ")
                    ))
                    .collect::<Vec<_>>()
                    .join("; ")
            ));
        }
    }
    let beams: Vec<&Shape> = shapes.iter().filter(|s| matches!(s.name, "beam" | "t-beam")).collect();
    for shape in &beams {
        bar.set_message(format!("{}: error against load", shape.name));
        bar.inc(1);
        match load_extrapolation(
            &root,
            selected(WarpMaterial::NeoHookean)?,
            shape,
            direction,
            field,
            lame,
            ctx.size,
        ) {
            Ok(plot) => out.lines.push(plot),
            Err(e) => out
                .failures
                .push(format!("nnwarp/{}: load extrapolation: {e:#}", shape.name)),
        }
    }
    if let Some(beam) = beams.first() {
        bar.set_message("beam: error against direction");
        bar.inc(1);
        match direction_extrapolation(&root, selected(WarpMaterial::NeoHookean)?, beam, lame, ctx.size) {
            Ok(plot) => out.lines.push(plot),
            Err(e) => out
                .failures
                .push(format!("nnwarp/beam: direction extrapolation: {e:#}")),
        }
    }
    for dt in TRAJECTORY_STEPS {
        bar.set_message(format!("trajectory at Δt = {dt} s"));
        bar.inc(1);
        match trajectory(selected(WarpMaterial::NeoHookean)?, direction, dt, ctx.size) {
            Ok((plot, note)) => {
                out.lines.push(plot);
                out.notes.push(note);
            }
            Err(e) => out.failures.push(format!("nnwarp/trajectory at Δt = {dt} s: {e:#}")),
        }
    }
    bar.finish_and_clear();
    Ok(out)
}

/// Scores the NNWarp model in `model_dir` (`cargo xtask train nnwarp`) on the `split`
/// sequences of the `nnwarp` dataset in `data_dir`: per frame after the first, `rel-error`
/// of the corrected linear displacement against the material's registered one, beside
/// modal warping and the linear displacement itself (scene `beam/<material>`, the
/// dataset's body), and NNWarp's displacements under `ctx.out/predictions/nnwarp/beam/`.
pub fn score_model(
    ctx: &EvalContext,
    model_dir: &Path,
    data_dir: &Path,
    split: &str,
) -> crate::Result<ExperimentOutput> {
    let (config, mlp) =
        load_model(model_dir).with_context(|| format!("loading the model in {}", model_dir.display()))?;
    let dataset = weft_data::WarpDataset::load(data_dir, &config.material)?;
    let gradients = Arc::new(NodalGradients::new(&dataset.body)?);
    let sequences: Vec<&weft_data::WarpSequence> = dataset.sequences.iter().filter(|s| s.split == split).collect();
    crate::error::ensure!(!sequences.is_empty(), "{} has no {split} sequence", data_dir.display());
    let scene = format!("beam/{}", config.material);
    let mut sums = [0.0f64; 3];
    let mut seconds = [0.0f64; 3];
    let (mut frames, mut predicted, mut truth) = (0usize, Vec::new(), Vec::new());
    for s in &sequences {
        // The dataset's body is already in the unit sphere: scale 1.
        let context = WarpContext::with_gradients(
            &dataset.body,
            gradients.clone(),
            &dataset.anchors,
            s.field,
            s.poisson,
            1.0,
        )?;
        let warp = NnWarp::new(context, mlp.clone());
        for (lin, reference) in s.linear.iter().zip(&s.nonlinear).skip(1) {
            let t = Instant::now();
            let corrected = warp.warp(lin)?;
            seconds[0] += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let modal = modal_warp(&gradients, lin)?;
            seconds[1] += t.elapsed().as_secs_f64();
            for (k, u) in [&corrected, &modal, lin].into_iter().enumerate() {
                sums[k] += rel_error(u, reference);
            }
            predicted.extend_from_slice(&corrected);
            truth.extend_from_slice(reference);
            frames += 1;
        }
    }
    crate::error::ensure!(frames > 0, "the {split} sequences hold no frame after the first");
    let mut out = ExperimentOutput::new("nnwarp", ctx.size);
    out.notes.push(format!(
        "nnwarp score: {} on the {} {split} sequences of {} ({frames} frames), against the registered {} shapes",
        model_dir.display(),
        sequences.len(),
        data_dir.display(),
        config.material
    ));
    for (k, method) in ["nnwarp", "modal-warping", "linear"].into_iter().enumerate() {
        let timing = Timing {
            seconds_per_frame: Some(seconds[k] / frames as f64),
            ground_truth_seconds_per_frame: None,
        };
        out.record(&scene, method, "rel-error", sums[k] / frames as f64, "1", timing);
        if let Some(r) = out.records.last_mut() {
            r.split = Some(split.into());
        }
    }
    let dir = ctx.out.join("predictions").join("nnwarp").join("beam");
    std::fs::create_dir_all(&dir)?;
    let v = dataset.body.num_vertices();
    weft_data::files::write_safetensors(
        &dir.join(format!("{}.safetensors", config.material)),
        &[
            weft_data::files::Array::f64("positions", vec![frames, v, 3], &predicted),
            weft_data::files::Array::f64("ground_truth", vec![frames, v, 3], &truth),
        ],
        std::collections::HashMap::from([(
            "units".to_string(),
            "displacements [frames, nodes, 3] in the dataset's unit-sphere units: NNWarp's (positions) and the \
             registered nonlinear (ground_truth)"
                .to_string(),
        )]),
    )?;
    Ok(out)
}
