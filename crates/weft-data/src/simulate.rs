//! One scene simulated into a directory, as `cargo xtask simulate` writes it: the scene's
//! TOML, its rest shape, `frames.safetensors`, `stats.json`, optionally one OBJ per frame,
//! and for a volume the last frame's displacement field as VTK. The overrides a command
//! line puts on a loaded scene are checked here too. Datasets of many sequences are
//! [`generate`](mod@crate::generate)'s; this writes one run.

use std::path::Path;

use serde::Serialize;
use weft_sim::scenes::volume::LimbResolution;
use weft_sim::{AnyScene, LoadedScene};

use crate::files::{progress_bar, write_json, write_safetensors, write_text};
use crate::record::{FrameStats, Recorder, Recording};
use crate::{Error, Result};

/// Settings given over a loaded scene's own (each applies to one kind of scene).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SceneOverrides {
    /// The limb's surface resolution by vertex count: 1410 (default) or 6890 (SMPL-size).
    pub vertices: Option<usize>,
    /// Cloth: Newton's globalisation (`line-search` or `trust-region`).
    pub globalization: Option<String>,
    /// Cloth: when Newton makes the Hessian positive definite.
    pub hessian: Option<String>,
    /// Cloth: at most this many Newton iterations per time step (at least 1).
    pub newton_budget: Option<usize>,
    /// Cloth: at most this many numeric factorisations per time step (at least 1).
    pub newton_factorizations: Option<usize>,
}

impl SceneOverrides {
    /// Puts the overrides on `scene`, refusing those its kind does not have.
    pub fn apply(&self, scene: &mut AnyScene) -> Result<()> {
        let invalid = |m: &str| Err(Error::Invalid(m.to_string()));
        match (&mut *scene, self.vertices) {
            (_, None) => {}
            (AnyScene::SoftTissue(s), Some(6890)) => s.resolution = LimbResolution::Smpl,
            (AnyScene::SoftTissue(s), Some(1410)) => s.resolution = LimbResolution::Default,
            (AnyScene::SoftTissue(_), Some(v)) => {
                return Err(Error::Invalid(format!(
                    "--vertices {v}: the limb comes in 1410 (default) and 6890 (SMPL-size) surface vertices"
                )));
            }
            _ => return invalid("--vertices applies to the limb scene only"),
        }
        match (&mut *scene, self.globalization.as_deref()) {
            (_, None) => {}
            (AnyScene::Cloth(c), Some(g)) => {
                c.globalization = Some(serde_json::from_value(serde_json::Value::String(g.into()))?);
            }
            _ => return invalid("--globalization applies to cloth scenes only"),
        }
        let (budget, factorizations) = (self.newton_budget, self.newton_factorizations);
        match (scene, self.hessian.as_deref()) {
            (_, None) if budget.is_none() && factorizations.is_none() => {}
            (AnyScene::Cloth(c), hessian) => {
                if budget == Some(0) {
                    return invalid(
                        "--newton-budget must be at least 1 (omit it to solve every step to the tolerance)",
                    );
                }
                if factorizations == Some(0) {
                    return invalid(
                        "--newton-factorizations must be at least 1 (omit it to factorise at every iteration)",
                    );
                }
                if let Some(h) = hessian {
                    c.hessian = Some(serde_json::from_value(serde_json::Value::String(h.into()))?);
                }
                if budget.is_some() {
                    c.newton_budget = budget;
                }
                if factorizations.is_some() {
                    c.newton_factorizations = factorizations;
                }
                c.validate()?;
            }
            _ => return invalid("--hessian, --newton-budget and --newton-factorizations apply to cloth scenes only"),
        }
        Ok(())
    }
}

/// `stats.json` of a run.
#[derive(Debug, Serialize)]
pub struct SimulateStats<'a> {
    pub scene: &'a str,
    pub vertices: usize,
    pub frames: usize,
    pub total_seconds: f64,
    pub mean_ms_per_frame: f64,
    pub mean_newton_iterations: f64,
    pub error: Option<&'a str>,
    pub per_frame: &'a [FrameStats],
}

impl<'a> SimulateStats<'a> {
    pub fn new(rec: &'a Recording) -> Self {
        Self {
            scene: &rec.scene,
            vertices: rec.vertices,
            frames: rec.per_frame.len(),
            total_seconds: rec.total_seconds,
            mean_ms_per_frame: 1e3 * rec.seconds_per_frame(),
            mean_newton_iterations: rec.mean_newton_iterations(),
            error: rec.error.as_deref(),
            per_frame: &rec.per_frame,
        }
    }
}

/// What [`simulate_into`] ran.
#[derive(Debug)]
pub struct SimulateReport {
    pub recording: Recording,
    /// The body's size in words, e.g. `4225 vertices` or `3969 nodes / 18432 tets`.
    pub what: String,
}

/// Runs `loaded` for its frames and writes the directory `out` (see the module
/// documentation; `obj`: one surface OBJ per frame in `out/obj/`). A run that stopped early
/// is written up to the failure and reported in [`Recording::error`], not as an error.
pub fn simulate_into(loaded: &LoadedScene, out: &Path, obj: bool, quiet: bool) -> Result<SimulateReport> {
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let mut recorder = Recorder::new(loaded)?;
    let name = loaded.scene.name().to_string();
    write_text(&out.join("scene.toml"), &loaded.scene.to_toml()?)?;
    let (faces, surface_vertex, what) = write_rest(&recorder, out)?;
    if obj {
        let dir = out.join("obj");
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    }
    let bar = progress_bar(quiet, loaded.scene.frames() as u64, &name, "frames")?;
    let recording = recorder.record(&name, loaded.scene.frames(), &bar, |m, r| {
        if obj {
            let x = r.positions();
            let p: Vec<_> = surface_vertex
                .iter()
                .map(|&v| nalgebra::Vector3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2]))
                .collect();
            weft_mesh::io::write_obj(&out.join(format!("obj/frame_{m:05}.obj")), &p, &faces)?;
        }
        Ok(())
    })?;
    bar.finish_and_clear();
    if let Recorder::Volume(s) = &recorder {
        // The last frame with its displacement field, for ParaView.
        let x = s.positions();
        let rest = s.mesh().flat_positions();
        let u: Vec<f64> = x.iter().zip(&rest).map(|(a, b)| a - b).collect();
        weft_mesh::io::write_vtk_tets(
            &out.join("final.vtk"),
            &weft_mesh::unflatten(&x),
            s.mesh().tets(),
            &[("displacement", 3, &u)],
        )?;
    }
    write_safetensors(
        &out.join("frames.safetensors"),
        &recording.to_arrays(),
        recording.metadata.clone(),
    )?;
    write_json(&out.join("stats.json"), &SimulateStats::new(&recording))?;
    Ok(SimulateReport { recording, what })
}

/// What [`simulate_guarded_into`] ran: the guard's per-frame reports and totals
/// (`guard.json`).
#[derive(Debug, Serialize)]
pub struct GuardedRun {
    pub scene: String,
    pub surrogate: String,
    pub settings: weft_sim::guard::GuardSettings,
    pub vertices: usize,
    pub total_seconds: f64,
    pub totals: weft_sim::guard::GuardTotals,
    pub per_frame: Vec<weft_sim::guard::GuardReport>,
}

/// The guard's settings from a command's tolerance — millimetres (mass-weighted RMS per
/// coordinate) or `truth` (the ground truth's own test, also when `None`) — and whether
/// to accept on the certified bound only. A tolerance that is not a positive, finite
/// number of millimetres is refused.
pub fn guard_settings(tolerance: Option<&str>, certified: bool) -> Result<weft_sim::guard::GuardSettings> {
    use weft_sim::guard::{Acceptance, GuardSettings};
    let mut s = match tolerance.map(str::trim) {
        None | Some("truth") => GuardSettings::ground_truth(),
        Some(t) => {
            let mm: f64 = t
                .parse()
                .map_err(|_| Error::Invalid(format!("guard tolerance {t:?}: a number of millimetres or `truth`")))?;
            GuardSettings::millimetres(mm)?
        }
    };
    if certified {
        s.acceptance = Acceptance::CertifiedBound;
    }
    Ok(s)
}

/// A guarded roll-out held in memory ([`simulate_guarded`]).
#[derive(Debug)]
pub struct GuardedRollout {
    pub run: GuardedRun,
    /// Flat positions `[F + 1, V, 3]` (m), the initial state first.
    pub positions: Vec<f64>,
    /// The cloth's rest mesh.
    pub rest: weft_mesh::TriMesh,
}

/// Runs the cloth scene `loaded` with `surrogate` proposing every frame under a guard of
/// `settings` (docs/GUARD.md), `bar` counting frames. Only cloth scenes have a guard
/// today; another kind is refused by name, as are a surrogate of another mesh, scene or
/// time step and bad settings (weft-sim's `Guard::new`).
pub fn simulate_guarded(
    loaded: &LoadedScene,
    surrogate: Box<dyn weft_sim::guard::Surrogate>,
    settings: weft_sim::guard::GuardSettings,
    bar: &indicatif::ProgressBar,
) -> Result<GuardedRollout> {
    let AnyScene::Cloth(scene) = &loaded.scene else {
        return Err(Error::Invalid(format!(
            "scene {}: a guarded roll-out needs a cloth scene (implicit Euler); volumes and soft tissue have no guard \
             yet",
            loaded.scene.name()
        )));
    };
    let mut sim = weft_sim::ClothSimulation::new(scene.clone(), loaded.base_dir.as_deref())?;
    let mut guard = weft_sim::guard::Guard::new(sim.integrator(), &scene.name, surrogate, settings)?;
    let rest = sim.mesh().clone();
    let mut positions = sim.integrator().positions().to_vec();
    let (clock, mut per_frame) = (std::time::Instant::now(), Vec::new());
    for _ in 0..scene.frames {
        let f = sim.step_guarded(&mut guard, None)?;
        positions.extend_from_slice(&f.positions);
        per_frame.push(f.report);
        bar.inc(1);
    }
    let run = GuardedRun {
        scene: scene.name.clone(),
        surrogate: guard.surrogate().name().to_string(),
        settings,
        vertices: rest.num_vertices(),
        total_seconds: clock.elapsed().as_secs_f64(),
        totals: *guard.totals(),
        per_frame,
    };
    Ok(GuardedRollout { run, positions, rest })
}

/// [`simulate_guarded`] written to `out`: `scene.toml`, `rest.obj`, `frames.safetensors`
/// (`positions` `[F + 1, V, 3]` in m, the initial state first) and `guard.json`
/// ([`GuardedRun`]).
pub fn simulate_guarded_into(
    loaded: &LoadedScene,
    surrogate: Box<dyn weft_sim::guard::Surrogate>,
    settings: weft_sim::guard::GuardSettings,
    out: &Path,
    quiet: bool,
) -> Result<GuardedRun> {
    let bar = progress_bar(quiet, loaded.scene.frames() as u64, loaded.scene.name(), "frames")?;
    let rollout = simulate_guarded(loaded, surrogate, settings, &bar)?;
    bar.finish_and_clear();
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    write_text(&out.join("scene.toml"), &loaded.scene.to_toml()?)?;
    let (rest, v) = (&rollout.rest, rollout.rest.num_vertices());
    weft_mesh::io::write_obj(&out.join("rest.obj"), rest.positions(), rest.faces())?;
    write_safetensors(
        &out.join("frames.safetensors"),
        &[crate::files::Array::f64(
            "positions",
            vec![rollout.positions.len() / (3 * v), v, 3],
            &rollout.positions,
        )],
        Default::default(),
    )?;
    write_json(&out.join("guard.json"), &rollout.run)?;
    Ok(rollout.run)
}

/// The surface written per frame with `obj`, as (faces, surface vertex → recorded vertex)
/// and the body's size in words.
type Surface = (Vec<[usize; 3]>, Vec<usize>, String);

/// Writes the rest shape into `out` and returns the surface written per frame.
fn write_rest(recorder: &Recorder, out: &Path) -> Result<Surface> {
    Ok(match recorder {
        Recorder::Cloth(s) => {
            let m = s.mesh();
            weft_mesh::io::write_obj(&out.join("rest.obj"), m.positions(), m.faces())?;
            let n = m.num_vertices();
            (m.faces().to_vec(), (0..n).collect::<Vec<_>>(), format!("{n} vertices"))
        }
        Recorder::Volume(s) => {
            let mesh = s.mesh();
            let surface = mesh.boundary_surface()?;
            weft_mesh::io::write_tetgen(&out.join("rest.node"), mesh)?;
            weft_mesh::io::write_obj(
                &out.join("rest_surface.obj"),
                surface.mesh.positions(),
                surface.mesh.faces(),
            )?;
            let what = format!("{} nodes / {} tets", mesh.num_vertices(), mesh.num_tets());
            (surface.mesh.faces().to_vec(), surface.volume_vertex, what)
        }
        Recorder::SoftTissue(s) => {
            let m = &s.surface().mesh;
            weft_mesh::io::write_obj(&out.join("rest.obj"), m.positions(), m.faces())?;
            let n = m.num_vertices();
            (m.faces().to_vec(), (0..n).collect(), format!("{n} surface vertices"))
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(name: &str) -> AnyScene {
        weft_sim::load(name, true).unwrap().scene
    }

    #[test]
    fn overrides_apply_to_their_kind_of_scene_only() {
        let limb = SceneOverrides {
            vertices: Some(6890),
            ..Default::default()
        };
        let mut s = scene("limb");
        limb.apply(&mut s).unwrap();
        assert!(matches!(&s, AnyScene::SoftTissue(t) if t.resolution == LimbResolution::Smpl));
        assert!(limb.apply(&mut scene("sheet-ms")).is_err());
        let odd = SceneOverrides {
            vertices: Some(5),
            ..Default::default()
        };
        assert!(odd.apply(&mut scene("limb")).unwrap_err().to_string().contains("1410"));
        let cloth = SceneOverrides {
            newton_budget: Some(2),
            hessian: Some("always".into()),
            ..Default::default()
        };
        let mut s = scene("sheet-ms");
        cloth.apply(&mut s).unwrap();
        assert!(matches!(&s, AnyScene::Cloth(c) if c.newton_budget == Some(2) && c.hessian.is_some()));
        assert!(cloth.apply(&mut scene("beam-linear")).is_err());
        let zero = SceneOverrides {
            newton_factorizations: Some(0),
            ..Default::default()
        };
        assert!(zero.apply(&mut scene("sheet-ms")).is_err());
        SceneOverrides::default().apply(&mut scene("beam-linear")).unwrap();
    }
}
