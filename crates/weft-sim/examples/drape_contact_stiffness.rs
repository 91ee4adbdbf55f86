//! The drape scene's ground truth at several contact stiffnesses (docs/DRAPE.md, "Contact
//! stiffness"): Newton iterations and time per pose, how far the sleeve sinks into the
//! contact margin, and how far each equilibrium lies from the first stiffness's.
//!
//! ```sh
//! cargo run --release -p weft-sim --example drape_contact_stiffness -- [POSES] [K1 K2 ...]
//! ```
//! Defaults: 5 poses (the stream of seed 7, as the scene's test draws them), stiffnesses
//! 1e4 and 1e3 N/m.

use nalgebra::Vector3;
use weft_sim::energies::{ObstaclePenalty, ObstacleShape};
use weft_sim::rng::SplitMix64;
use weft_sim::scenes::drape::{Drape, DrapeParams};
use weft_sim::scenes::soft_tissue::ArmPose;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let poses: usize = args.first().map(|a| a.parse()).transpose()?.unwrap_or(5);
    let mut stiffnesses: Vec<f64> = args.iter().skip(1).map(|a| a.parse()).collect::<Result<_, _>>()?;
    if stiffnesses.is_empty() {
        stiffnesses = vec![1e4, 1e3];
    }
    let scenes = stiffnesses
        .iter()
        .map(|&k| {
            Drape::new(DrapeParams {
                contact_stiffness: k,
                ..DrapeParams::standard()
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let margin = DrapeParams::standard().contact_margin;
    println!(
        "pose | stiffness (N/m) | Newton iterations | time (s) | deepest into the margin (µm) | RMS / max distance to the first stiffness's equilibrium (mm)"
    );
    let mut rng = SplitMix64::new(7);
    let mut totals = vec![(0usize, 0.0f64); scenes.len()];
    for p in 0..poses {
        let pose = ArmPose::sample(&mut rng);
        let body = scenes[0].body(&pose)?;
        let n = scenes[0].sleeve().num_vertices();
        // Unit stiffness and no margin: only its signed distance is used.
        let distance = ObstaclePenalty::new(ObstacleShape::mesh(&body)?, n, 1.0, 0.0)?;
        let mut first: Option<Vec<f64>> = None;
        for (s, (scene, &k)) in scenes.iter().zip(&stiffnesses).enumerate() {
            let e = match scene.solve(&pose) {
                Ok(e) => e,
                Err(err) => {
                    println!("{p} | {k:.0e} | did not converge: {err}");
                    continue;
                }
            };
            let closest = e
                .truth
                .chunks(3)
                .map(|x| distance.signed_distance(&Vector3::new(x[0], x[1], x[2])))
                .fold(f64::INFINITY, f64::min);
            let (rms, max) = match &first {
                Some(f) => {
                    let d: Vec<f64> = f
                        .chunks(3)
                        .zip(e.truth.chunks(3))
                        .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]).hypot(a[2] - b[2]))
                        .collect();
                    let rms = (d.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
                    (rms * 1e3, d.iter().fold(0.0f64, |m, x| m.max(*x)) * 1e3)
                }
                None => (0.0, 0.0),
            };
            let t = e.report.time.as_secs_f64();
            totals[s].0 += e.report.iterations;
            totals[s].1 += t;
            println!(
                "{p} | {k:.0e} | {} | {t:.2} | {:.2} | {rms:.4} / {max:.4}",
                e.report.iterations,
                (margin - closest) * 1e6
            );
            first.get_or_insert(e.truth);
        }
    }
    for ((its, t), k) in totals.iter().zip(&stiffnesses) {
        println!("all | {k:.0e} | {its} | {t:.2} | | ");
    }
    Ok(())
}
