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

//!
//! One file per phase: `data` (the bodies), `studies` (the networks trained on
//! growing data, one chosen on validation), `scoring` (every method against the
//! nonlinear reference, and [`score_model`] for a model trained outside the evaluation),
//! `figures` (Table 1's timings, the extrapolation and trajectory figures).

pub(super) mod data;
mod figures;
mod scoring;
mod studies;

use std::path::Path;

use nalgebra::Vector3;
use weft_nn::nnwarp::WarpTrainingSettings;
use weft_sim::energies::{LameParameters, Material};
use weft_sim::warp::FieldDirection;

use crate::error::Context;
use crate::evaluate::context::{EvalContext, generate_dataset};
use crate::records::ExperimentOutput;
use data::{Shape, shapes};
use figures::{direction_extrapolation, load_extrapolation, timing_table, trajectory};
use scoring::{Bench, score_scene};
use studies::{data_size_study, study_report};
use weft_data::Size;

pub use scoring::score_model;

/// Linear answers' largest displacement at the evaluated loads (unit-sphere units).
pub(super) const LEVELS: [f64; 3] = [0.5, 1.0, 1.5];
/// The evaluation field: `hemisphere_direction(α = 1.2, β = 0.6)`, inside the trained
/// octant but drawn by no training sequence's seed.
pub(super) const FIELD_ANGLES: (f64, f64) = (1.2, 0.6);
/// The warped linear solve's fixed point: relative change between solves, and the most
/// solves allowed.
pub(super) const WARP_TOLERANCE: f64 = 1e-4;
pub(super) const WARP_SOLVES: usize = 100;
/// Newton load increments of the nonlinear reference from one load to the next.
pub(super) const REFERENCE_STEPS: usize = 4;
/// Newton iterations per increment, and halvings of an increment, before the reference
/// gives up on a load (reported under failures).
pub(super) const REFERENCE_NEWTON_ITERATIONS: usize = 50;
pub(super) const REFERENCE_SUBDIVISIONS: usize = 3;
/// The time steps of the trajectory figure (NNWarp Fig. 15 shows two).
const TRAJECTORY_STEPS: [f64; 2] = [0.01, 0.04];
pub(super) const YOUNG: f64 = 1e5;
pub(super) const POISSON: f64 = 0.3;
pub(super) const DENSITY: f64 = 1000.0;

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

/// Seeds per material: one at quick size (CI), three otherwise (the claims need three).
fn seeds(size: Size) -> Vec<u64> {
    match size {
        Size::Quick => vec![0],
        _ => vec![0, 1, 2],
    }
}

pub fn run(ctx: &EvalContext) -> crate::Result<ExperimentOutput> {
    let mut out = ExperimentOutput::new("nnwarp", ctx.size);
    let root = ctx.out.join("nnwarp");
    let data = root.join("data");
    let stopped = generate_dataset(ctx, weft_data::nnwarp::NAME, &data).context("nnwarp dataset")?;
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
        studies.push(data_size_study(ctx, &root, &data, m, &config, &seeds)?);
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
    timing_table(&mut out, ctx.size, &shapes, selected(WarpMaterial::NeoHookean)?, lame)?;
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
            bar.set_message(format!("{}/{}", shape.name, m.key()));
            bar.inc(1);
            let finals = &studies
                .iter()
                .find(|s| s.material == m)
                .context("a material without a trained model")?
                .finals;
            score_scene(&mut out, &root, &mut bench, m, finals, &seeds, field, lame)?;
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
