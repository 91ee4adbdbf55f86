//! A trained NNWarp network run on a volumetric scene (NNWarp §6), for `cargo xtask
//! warp`: the scene and the model read and checked, the run (against the full FEM
//! reference when asked) with a VTK file every few frames, and `summary.json`. It does
//! not print: [`WarpScene::warning`] and [`WarpSceneReport::line`] are what a command says.

use std::path::{Path, PathBuf};

use weft_sim::{AnyScene, VolumeScene, VolumeSimulation};

use crate::nnwarp::{
    NnWarpSimulation, NodeMlp, ReferenceTwins, WarpRunSetup, WarpRunSummary, WarpTrainingSettings, load_model,
    run_against_reference, write_frame_vtk,
};
use crate::{Error, Result};

/// What a warp run is asked for.
#[derive(Debug, Clone, Copy)]
pub struct WarpSceneParams<'a> {
    /// The model directory (`cargo xtask train nnwarp --out`).
    pub model: &'a Path,
    /// A built-in volumetric scene's name or a scene file.
    pub scene: &'a str,
    /// Where the frames' VTK files and `summary.json` go.
    pub out: &'a Path,
    /// Frames to run instead of the scene's.
    pub frames: Option<usize>,
    /// A VTK file every this many frames (and the last), at least 1.
    pub every: usize,
    /// Run the full nonlinear FEM beside it and record the per-node error.
    pub reference: bool,
    /// The scene's quick size.
    pub quick: bool,
}

/// A warp run ready to start: its scene and model read.
#[derive(Debug)]
pub struct WarpScene<'a> {
    params: WarpSceneParams<'a>,
    scene: VolumeScene,
    base_dir: Option<PathBuf>,
    config: WarpTrainingSettings,
    mlp: NodeMlp,
}

/// What a warp run measured, and the line a command says of it.
#[derive(Debug, Clone)]
pub struct WarpSceneReport {
    pub summary: WarpRunSummary,
    pub line: String,
}

impl<'a> WarpScene<'a> {
    /// Reads the scene (a volumetric one) and the model.
    pub fn load(params: WarpSceneParams<'a>) -> Result<Self> {
        if params.every == 0 {
            return Err(Error::InvalidFlag {
                flag: "--every",
                reason: "must be at least 1",
            });
        }
        let loaded = weft_sim::load(params.scene, params.quick)?;
        let AnyScene::Volume(mut scene) = loaded.scene else {
            return Err(Error::NotVolumetric {
                scene: params.scene.to_string(),
            });
        };
        if let Some(f) = params.frames {
            scene.frames = f;
        }
        let (config, mlp) = load_model(params.model).map_err(|e| Error::Load {
            path: params.model.display().to_string(),
            source: Box::new(e),
        })?;
        Ok(Self {
            params,
            scene,
            base_dir: loaded.base_dir,
            config,
            mlp,
        })
    }

    /// A network learns one material's nonlinearity (Luo et al. Eq. 6-7); on a scene of
    /// another it still runs, for studies across materials, but its answer is not that
    /// material's: what to warn of then.
    pub fn warning(&self) -> Option<String> {
        let scene_material = weft_data::nnwarp::material_key(self.scene.material);
        (self.config.material != scene_material).then(|| {
            format!(
                "warning: {} was trained on {}, but {} is {}: the correction is applied outside its training{}",
                self.params.model.display(),
                self.config.material,
                self.scene.name,
                scene_material,
                if self.params.reference {
                    " (the error against the reference measures that)"
                } else {
                    ""
                }
            )
        })
    }

    /// Runs the scene, writes its frames and `summary.json`.
    pub fn run(self) -> Result<WarpSceneReport> {
        let (p, scene) = (self.params, &self.scene);
        // The reference twin builds the body, anchors and loads once; the linear twin shares them.
        let mut reference_sim = VolumeSimulation::new(scene.clone(), self.base_dir.as_deref())?;
        let mut runtime = NnWarpSimulation::new(&reference_sim, self.mlp)?;
        let mesh = reference_sim.mesh().clone();
        let twins = p.reference.then(|| ReferenceTwins {
            reference: &mut reference_sim,
            others: Vec::new(),
        });
        let rest = mesh.flat_positions();
        std::fs::create_dir_all(p.out).map_err(|source| Error::CreateDir {
            path: p.out.display().to_string(),
            source,
        })?;
        let report = run_against_reference(&mut runtime, twins, scene.frames, |f| {
            if f.frame % p.every == 0 || f.frame == scene.frames {
                write_frame_vtk(p.out, f, &rest, &mesh)?;
            }
            Ok::<_, Error>(())
        })
        .map_err(|e| Error::WarpRun { source: Box::new(e) })?;
        let setup = WarpRunSetup {
            scene: &scene.name,
            model: p.model,
            material: &self.config.material,
            reference_material: scene.material.name(),
            mesh: &mesh,
            factorization_seconds: runtime.linear().factorization_seconds(),
        };
        let summary = WarpRunSummary::new(&setup, &report, scene.frames);
        weft_data::files::write_json(&p.out.join("summary.json"), &summary)?;
        let line = format!(
            "{}: {} frames, linear solve {:.2} ms + NNWarp {:.2} ms per frame{} → {}",
            scene.name,
            scene.frames,
            1e3 * summary.solve_seconds_per_frame,
            1e3 * summary.nnwarp_seconds_per_frame,
            summary
                .reference_seconds_per_frame
                .map_or(String::new(), |s| format!(", full FEM {:.1} ms per frame", 1e3 * s)),
            p.out.display()
        );
        Ok(WarpSceneReport { summary, line })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(every: usize, scene: &str) -> WarpSceneParams<'_> {
        WarpSceneParams {
            model: Path::new("no-such-model"),
            scene,
            out: Path::new("no-such-out"),
            frames: None,
            every,
            reference: false,
            quick: true,
        }
    }

    #[test]
    fn a_run_is_refused_before_anything_is_read() {
        let e = WarpScene::load(params(0, "beam")).unwrap_err();
        assert_eq!(e.to_string(), "--every must be at least 1");
    }

    #[test]
    fn a_cloth_scene_is_not_warped() {
        let e = WarpScene::load(params(1, "sheet-ms")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "sheet-ms is not a volumetric scene; NNWarp warps tetrahedral bodies"
        );
    }
}
