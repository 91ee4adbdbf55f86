//! How unique the drape scene's equilibrium is (docs/DRAPE.md): for poses of the stream
//! the scene's tests draw (seed 7), the ground truth from the kinematic guess, then the
//! same pose solved from perturbed starts — the guess plus 2 mm of seeded noise, and the
//! equilibrium of a nearby pose (elbow + 0.05 rad) — and how far each lands from the
//! first. The spread is the floor below which an error measures which equilibrium the
//! solver picked rather than the physics.
//!
//! ```sh
//! cargo run --release -p weft-sim --example drape_uniqueness -- [--scene sleeve|loose] [--poses N]
//!     [--young N/m] [--density kg/m²] [--bend N·m] [--offset m] [--shoulder rad] [--twist rad] [--elbow-max rad]
//!     [--settle STEPS] [--guess-half-width m]
//! ```
//! Defaults: the loose sleeve, 10 poses. With `--poses 0` it only builds the scene, which
//! checks that the kinematic guess does not fold over the pose range (a typed error if it
//! does); `--guess-half-width 0` binds the guess to the body instead of skinning it.

use nalgebra::Vector3;
use weft_sim::energies::{ObstaclePenalty, ObstacleShape};
use weft_sim::rng::SplitMix64;
use weft_sim::scenes::drape::{Drape, DrapeExample, DrapeParams};

fn rms_max_mm(a: &[f64], b: &[f64]) -> (f64, f64) {
    let d: Vec<f64> = a
        .chunks(3)
        .zip(b.chunks(3))
        .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]).hypot(a[2] - b[2]))
        .collect();
    let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
    (rms * 1e3, d.iter().fold(0.0f64, |m, x| m.max(*x)) * 1e3)
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1));
    if args.iter().any(|a| a == "--help" || a == "-h") {
        println!(
            "drape_uniqueness [--scene sleeve|loose] [--poses N] [--young N/m] [--density kg/m²] [--bend N·m] \
             [--offset m] [--shoulder rad] [--twist rad] [--elbow-max rad] [--settle STEPS] [--guess-half-width m (0: bind to the body)]"
        );
        return Ok(());
    }
    let mut params = match flag("--scene").map(String::as_str) {
        None | Some("loose") => DrapeParams::loose(),
        Some("sleeve") => DrapeParams::standard(),
        Some(other) => return Err(format!("unknown scene {other}: sleeve or loose").into()),
    };
    let number = |name: &str| flag(name).map(|v| v.parse::<f64>()).transpose();
    let poses = number("--poses")?.unwrap_or(10.0) as usize;
    if let Some(v) = number("--young")? {
        params.young = v;
    }
    if let Some(v) = number("--density")? {
        params.density = v;
    }
    if let Some(v) = number("--bend")? {
        params.bend_stiffness = v;
    }
    if let Some(v) = number("--offset")? {
        params.offset = v;
    }
    if let Some(v) = number("--guess-half-width")? {
        params.skinned_guess_half_width = v;
    }
    if let Some(v) = number("--shoulder")? {
        params.shoulder_range = v;
    }
    if let Some(v) = number("--twist")? {
        params.twist_range = v;
    }
    if let Some(v) = number("--elbow-max")? {
        params.elbow_flexion[1] = v;
    }
    if let Some(v) = number("--settle")? {
        params.settle_steps = v as usize;
    }
    let drape = Drape::new(params)?;
    let n = drape.sleeve().num_vertices();
    println!("{params:?}");
    println!(
        "pose | angles (rad) | iterations (settle + Newton) | time incl. settle (s) | guess to truth RMS / max (mm) | deepest \
         into the body (mm) | from noise: RMS / max (mm), energy change (J) | from elbow + 0.05: RMS / max (mm)"
    );
    let mut rng = SplitMix64::new(7);
    let (mut converged, mut iterations, mut seconds, mut guess_rms) = (0, 0usize, 0.0, Vec::new());
    let mut floor = Vec::new();
    for p in 0..poses {
        let pose = drape.sample_pose(&mut rng);
        let a = pose.angles();
        let clock = std::time::Instant::now();
        let reference = match drape.solve(&pose) {
            Ok(e) => e,
            Err(err) => {
                println!("{p} | {a:.3?} | did not converge: {err}");
                continue;
            }
        };
        let took = clock.elapsed().as_secs_f64();
        converged += 1;
        iterations += reference.settle_iterations + reference.report.iterations;
        seconds += took;
        let (g_rms, g_max) = rms_max_mm(&reference.guess, &reference.truth);
        guess_rms.push(g_rms);
        let body = drape.body(&pose)?;
        let distance = ObstaclePenalty::new(ObstacleShape::mesh(&body)?, n, 1.0, 0.0)?;
        let deepest = reference
            .truth
            .chunks(3)
            .map(|x| -distance.signed_distance(&Vector3::new(x[0], x[1], x[2])))
            .fold(f64::NEG_INFINITY, f64::max);
        let mut noise_rng = SplitMix64::new(1000 + p as u64);
        let noisy: Vec<f64> = reference
            .guess
            .iter()
            .map(|x| x + noise_rng.uniform(-2e-3, 2e-3))
            .collect();
        let compare = |e: Result<DrapeExample, weft_sim::Error>, floor: &mut Vec<f64>| match e {
            Ok(e) => {
                let (rms, max) = rms_max_mm(&reference.truth, &e.truth);
                floor.push(rms);
                format!(
                    "{rms:.3} / {max:.3}, {:+.2e}",
                    e.report.energy - reference.report.energy
                )
            }
            Err(err) => format!("did not converge ({err})"),
        };
        let from_noise = compare(drape.solve_from(&pose, Some(&noisy)), &mut floor);
        let mut near = pose;
        near.elbow_flexion += 0.05;
        let from_near = match drape.solve(&near) {
            Ok(e) => compare(drape.solve_from(&pose, Some(&e.truth)), &mut floor),
            Err(err) => format!("nearby pose did not converge ({err})"),
        };
        println!(
            "{p} | {a:.3?} | {} + {} | {:.2} | {g_rms:.2} / {g_max:.2} | {:.3} | {from_noise} | {from_near}",
            reference.settle_iterations,
            reference.report.iterations,
            took,
            deepest * 1e3,
        );
    }
    let c = converged.max(1) as f64;
    println!(
        "converged {converged} of {poses}; mean iterations {:.1}, mean time per pose {:.2} s; guess to truth \
         RMS median {:.2} mm; floor (RMS to the reference from the perturbed starts) median {:.3} mm, 90th \
         percentile {:.3} mm",
        iterations as f64 / c,
        seconds / c,
        percentile(&mut guess_rms, 0.5),
        percentile(&mut floor.clone(), 0.5),
        percentile(&mut floor, 0.9),
    );
    Ok(())
}
