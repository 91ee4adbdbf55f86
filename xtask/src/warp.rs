//! `cargo xtask warp`: NNWarp's runtime on a volumetric scene (NNWarp §6).
//!
//! The scene's body runs as linear elasticity with a constant, pre-factorised system
//! (backward Euler with the scene's time step and damping, or static load increments for
//! a static scene), each node's load rotated back to its rest orientation first, and every
//! frame corrected node by node by the trained network (`weft_nn::nnwarp::NnWarpSimulation`).
//! With `--reference` the scene also runs as it is written (full nonlinear FEM), and each
//! frame's VTK carries the per-node error against it.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;
use nalgebra::Vector3;
use weft_nn::nnwarp::{NnWarpSimulation, load_model, rel_error};
use weft_sim::{AnyScene, VolumeSimulation};

use weft_data::files::write_json;

#[derive(Args)]
pub struct WarpArgs {
    /// A model directory written by `cargo xtask train nnwarp`.
    #[arg(long)]
    model: PathBuf,
    /// A volumetric scene: a built-in name (`beam-neo-hookean`, …) or a TOML file.
    #[arg(long)]
    scene: String,
    /// Output directory: `frame-NNNN.vtk` per written frame and `summary.json`.
    #[arg(long)]
    out: PathBuf,
    /// Frames to run (default: the scene's).
    #[arg(long)]
    frames: Option<usize>,
    /// Write every N-th frame's VTK (the last frame is always written).
    #[arg(long, default_value_t = 1)]
    every: usize,
    /// Also run the scene's full nonlinear FEM and write the per-node error against it.
    #[arg(long)]
    reference: bool,
    /// The built-in scene's small variant.
    #[arg(long)]
    quick: bool,
}

pub fn run(args: WarpArgs) -> anyhow::Result<()> {
    if args.every == 0 {
        bail!("--every must be at least 1");
    }
    let loaded = weft_sim::load(&args.scene, args.quick)?;
    let AnyScene::Volume(mut scene) = loaded.scene else {
        bail!(
            "{} is not a volumetric scene; NNWarp warps tetrahedral bodies",
            args.scene
        );
    };
    if let Some(f) = args.frames {
        scene.frames = f;
    }
    let base_dir = loaded.base_dir.as_deref();
    let (config, mlp) = load_model(&args.model).with_context(|| format!("loading {}", args.model.display()))?;
    let scene_material = weft_data::nnwarp::material_key(scene.material);
    if config.material != scene_material {
        // A network learns one material's nonlinearity (Luo et al. Eq. 6-7); it still
        // runs, for studies across materials, but its answer is not that material's.
        eprintln!(
            "warning: {} was trained on {}, but {} is {}: the correction is applied outside its training{}",
            args.model.display(),
            config.material,
            scene.name,
            scene_material,
            if args.reference {
                " (the error against the reference measures that)"
            } else {
                ""
            }
        );
    }
    // The reference twin builds the body, anchors and loads once; the linear twin shares them.
    let reference_sim = VolumeSimulation::new(scene.clone(), base_dir)?;
    let mut runtime = NnWarpSimulation::new(&reference_sim, mlp)?;
    let mesh = reference_sim.mesh().clone();
    let mut reference = if args.reference { Some(reference_sim) } else { None };
    let rest = mesh.flat_positions();
    let n = rest.len();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating the output directory {}", args.out.display()))?;
    let mut frames = Vec::new();
    let (mut solve_seconds, mut warp_seconds, mut reference_seconds) = (0.0, 0.0, 0.0);
    for k in 1..=scene.frames {
        let frame = runtime.step()?;
        solve_seconds += frame.solve_seconds;
        warp_seconds += frame.warp_seconds;
        let (u, u_lin) = (frame.warped, frame.linear);
        let mut record = serde_json::json!({ "frame": k });
        let mut error: Option<Vec<f64>> = None;
        if let Some(sim) = &mut reference {
            let t = Instant::now();
            let x = sim.step().with_context(|| format!("reference frame {k}"))?.positions;
            reference_seconds += t.elapsed().as_secs_f64();
            let u_ref: Vec<f64> = x.iter().zip(&rest).map(|(x, r)| x - r).collect();
            record["rel_error_nnwarp"] = rel_error(&u, &u_ref).into();
            record["rel_error_linear_solve"] = rel_error(&u_lin, &u_ref).into();
            error = Some(
                (0..n / 3)
                    .map(|i| {
                        Vector3::new(
                            u[3 * i] - u_ref[3 * i],
                            u[3 * i + 1] - u_ref[3 * i + 1],
                            u[3 * i + 2] - u_ref[3 * i + 2],
                        )
                        .norm()
                    })
                    .collect(),
            );
        }
        frames.push(record);
        if k % args.every == 0 || k == scene.frames {
            let positions: Vec<Vector3<f64>> = (0..n / 3)
                .map(|i| {
                    Vector3::new(
                        rest[3 * i] + u[3 * i],
                        rest[3 * i + 1] + u[3 * i + 1],
                        rest[3 * i + 2] + u[3 * i + 2],
                    )
                })
                .collect();
            let mut fields: Vec<weft_mesh::io::PointField<'_>> =
                vec![("displacement", 3, &u[..]), ("linear_displacement", 3, &u_lin[..])];
            if let Some(e) = &error {
                fields.push(("error", 1, &e[..]));
            }
            weft_mesh::io::write_vtk_tets(
                &args.out.join(format!("frame-{k:04}.vtk")),
                &positions,
                mesh.tets(),
                &fields,
            )?;
        }
    }
    let frames_run = scene.frames.max(1) as f64;
    let summary = serde_json::json!({
        "scene": scene.name,
        "model": args.model.display().to_string(),
        "material": config.material,
        "reference_material": scene.material.name(),
        "nodes": mesh.num_vertices(),
        "tets": mesh.num_tets(),
        "frames": frames,
        "factorization_seconds": runtime.linear().factorization_seconds(),
        "solve_seconds_per_frame": solve_seconds / frames_run,
        "nnwarp_seconds_per_frame": warp_seconds / frames_run,
        "reference_seconds_per_frame": if args.reference { Some(reference_seconds / frames_run) } else { None },
    });
    write_json(&args.out.join("summary.json"), &summary)?;
    eprintln!(
        "{}: {} frames, linear solve {:.2} ms + NNWarp {:.2} ms per frame{} → {}",
        scene.name,
        scene.frames,
        1e3 * solve_seconds / frames_run,
        1e3 * warp_seconds / frames_run,
        if args.reference {
            format!(", full FEM {:.1} ms per frame", 1e3 * reference_seconds / frames_run)
        } else {
            String::new()
        },
        args.out.display()
    );
    Ok(())
}
