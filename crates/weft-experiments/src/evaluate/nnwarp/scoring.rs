//! The nnwarp experiment's scoring: a shape prepared for one field direction ([`Bench`]),
//! every method's `rel-error` at a load against the material's static nonlinear
//! equilibrium ([`Reference`], cached on disk), a shape × material scene scored over the
//! loads, and [`score_model`] for a model trained outside the evaluation.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use nalgebra::Vector3;
use weft_nn::nnwarp::{NnWarp, WarpContext, load_model, rel_error};
use weft_sim::energies::{LameParameters, Material, TetElasticity};
use weft_sim::warp::{
    FieldDirection, NodalGradients, RotationStrainWarp, modal_warp, unit_sphere_normalization, warped_static_solve,
};
use weft_sim::{LinearSolve, PrefactorizedLinear, Quasistatic};

use super::data::Shape;
use super::{
    DENSITY, FIELD_ANGLES, LEVELS, POISSON, REFERENCE_NEWTON_ITERATIONS, REFERENCE_STEPS, REFERENCE_SUBDIVISIONS,
    WARP_SOLVES, WARP_TOLERANCE, WarpMaterial, YOUNG, material_of,
};
use crate::error::Context;
use crate::evaluate::context::Scoring;
use crate::records::{ExperimentOutput, SeedFigure, Timing};

/// One shape under material `m` (NNWarp with each of `finals`, one network per seed of
/// `seeds`, in order):
/// every method's `rel-error` averaged over the loads against the nonlinear reference,
/// NNWarp's spread over its seeds, and a note of the loads; a load the reference or the
/// warped solve cannot reach ends the loads and is reported under failures.
pub(super) fn score_scene(
    out: &mut ExperimentOutput,
    root: &Path,
    bench: &mut Bench,
    m: WarpMaterial,
    finals: &[PathBuf],
    seeds: &[u64],
    field: FieldDirection,
    lame: LameParameters,
) -> crate::Result<()> {
    let shape = bench.shape;
    let scene = format!("{}/{}", shape.name, m.key());
    let nnwarp = finals
        .iter()
        .map(|dir| bench.nnwarp(dir, field))
        .collect::<crate::Result<Vec<_>>>()?;
    let mut reference = Reference::new(root, bench, m, lame, &field_tag(FIELD_ANGLES.0))?;
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
        return Ok(());
    }
    let levels = per_level.len() as f64;
    for (k, name) in METHODS.iter().enumerate() {
        let timing = Timing::new(tallies[k].seconds / levels, reference.seconds / levels);
        if *name == "nnwarp" {
            // One record per seed (each seed's error averaged over the loads), their mean
            // and their spread.
            let per_seed: Vec<(u64, f64)> = seeds
                .iter()
                .copied()
                .zip(seed_errors.iter().map(|e| e / levels))
                .collect();
            let figure = SeedFigure {
                scene: &scene,
                method: name,
                metric: "rel-error",
                split: Some(shape.split),
                unit: "1",
                timing,
                paper: None,
            };
            out.record_over_seeds(&figure, &per_seed);
        } else {
            out.record(&scene, name, "rel-error", tallies[k].error / levels, "1", timing);
            out.split(shape.split);
        }
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
    Ok(())
}

/// Per method: summed rel-error and seconds over the loads.
#[derive(Default, Clone, Copy)]
struct Tally {
    error: f64,
    seconds: f64,
}

/// The methods scored, in the records' order.
pub(super) const METHODS: [&str; 4] = ["nnwarp", "modal-warping", "rotation-strain-warping", "linear"];

/// One shape prepared for one field direction: the pre-factorised linear system, the
/// warps' shared gradient fit, rotation-strain warping's factorised Poisson system, and
/// the unit load.
pub(super) struct Bench<'a> {
    shape: &'a Shape,
    rest: Vec<f64>,
    fixed: Vec<bool>,
    /// The directional field at 1 m/s² (N, flat).
    unit_force: Vec<f64>,
    linear: PrefactorizedLinear,
    gradients: Arc<NodalGradients>,
    rsw: RotationStrainWarp,
    /// Unit-sphere scale of the shape (1/m).
    pub(super) scale: f64,
    /// The largest node displacement of the linear answer to `unit_force` (m).
    pub(super) reach: f64,
}

impl<'a> Bench<'a> {
    pub(super) fn new(shape: &'a Shape, direction: Vector3<f64>, lame: LameParameters) -> crate::Result<Self> {
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
    pub(super) fn load(&self, level: f64) -> Vec<f64> {
        let a = level / (self.reach * self.scale);
        self.unit_force.iter().map(|f| f * a).collect()
    }

    pub(super) fn nnwarp(&self, model_dir: &Path, field: FieldDirection) -> crate::Result<NnWarp> {
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
    pub(super) fn score(&mut self, nnwarps: &[NnWarp], reference: &mut Reference, level: f64) -> crate::Result<Scored> {
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
pub(super) struct Scored {
    /// NNWarp's is the mean over its seeds.
    pub(super) errors: [f64; 4],
    seconds: [f64; 4],
    /// Linear solves the warped fixed point took.
    solves: usize,
    /// NNWarp's error per seed.
    nnwarp_seeds: Vec<f64>,
}

/// A material's static nonlinear equilibrium, continued from load to load, each one
/// cached on disk: the limb's take minutes, and an interrupted evaluation resumes from
/// them.
pub(super) struct Reference {
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
    pub(super) fn new(
        root: &Path,
        bench: &Bench,
        m: WarpMaterial,
        lame: LameParameters,
        field: &str,
    ) -> crate::Result<Self> {
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
pub(super) fn field_tag(alpha: f64) -> String {
    format!("E{YOUNG}-nu{POISSON}-alpha-{alpha:.3}-beta-{:.3}", FIELD_ANGLES.1)
}

/// The largest node displacement of flat displacements `u`.
fn max_node_displacement(u: &[f64]) -> f64 {
    u.chunks_exact(3)
        .map(|c| Vector3::new(c[0], c[1], c[2]).norm())
        .fold(0.0, f64::max)
}

/// Scores the NNWarp model in `model_dir` (`cargo xtask train nnwarp`) on the `split`
/// sequences of the `nnwarp` dataset in `data_dir`: per frame after the first, `rel-error`
/// of the corrected linear displacement against the material's registered one, beside
/// modal warping and the linear displacement itself (scene `beam/<material>`, the
/// dataset's body), and NNWarp's displacements under `ctx.out/predictions/nnwarp/beam/`.
pub fn score_model(scoring: &Scoring) -> crate::Result<ExperimentOutput> {
    let (ctx, data_dir, split) = (scoring.ctx, scoring.data_dir, scoring.split);
    let (config, mlp) = scoring.load_model(load_model)?;
    let dataset = weft_data::WarpDataset::load(data_dir, &config.material)?;
    let gradients = Arc::new(NodalGradients::new(&dataset.body)?);
    let sequences: Vec<&weft_data::WarpSequence> = dataset.sequences.iter().filter(|s| s.split == split).collect();
    scoring.require(sequences.len(), "sequence")?;
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
    let mut out = scoring.output(format_args!(
        "on the {} {split} sequences of {} ({frames} frames), against the registered {} shapes",
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
        out.split(split);
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
