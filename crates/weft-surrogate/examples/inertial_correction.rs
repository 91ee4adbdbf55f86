//! The inertial correction on a cloth dataset (docs/GUARD.md, "A surrogate to guard"):
//! fit, the validation scores of every ridge weight, the one-step errors beside the
//! inertial predictor's on each split, and guarded replays of every sequence at a few
//! tolerances.
//!
//! ```sh
//! cargo xtask dataset sheet-ms --size quick --out /tmp/q-sheet-ms
//! cargo run --release -p weft-surrogate --example inertial_correction -- /tmp/q-sheet-ms [FRAMES]
//! ```
//! The replays run the first `FRAMES` frames (default: all) of every sequence.

use weft_data::ClothDataset;
use weft_sim::ClothSimulation;
use weft_sim::guard::{Guard, GuardSettings, InertialPredictor, Surrogate};
use weft_surrogate::inertial_correction::{InertialCorrection, InertialCorrectionSettings};

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

fn replay(
    data: &ClothDataset,
    frames: usize,
    surrogate: Box<dyn Surrogate>,
    settings: GuardSettings,
) -> Result<String, Box<dyn std::error::Error>> {
    let sim = ClothSimulation::new(data.scene.clone(), Some(&data.dir))?;
    let mut integrator = sim.into_integrator();
    let mut guard = Guard::new(&integrator, &data.scene.name, surrogate, settings)?;
    let (mut errors, mut seconds) = (Vec::new(), 0.0);
    for (s, seq) in data.sequences.iter().enumerate() {
        integrator.set_state(seq.frame(0), seq.frame(0))?;
        for m in 1..seq.num_frames().min(frames + 1) {
            let prescribed = data.prescribed_at(s, m);
            let r = guard.step(&mut integrator, m, &prescribed, Some(seq.frame(m)))?;
            errors.push(r.error.map_or(f64::NAN, |e| e.m_rms_mm));
            seconds += r.seconds.proposal + r.seconds.guard + r.seconds.correction;
        }
    }
    let t = guard.totals();
    Ok(format!(
        "accepted {}/{}, Newton iterations {}, M_rms against the dataset {:.3} mm, {:.1} ms per frame",
        t.accepted,
        t.frames,
        t.newton_iterations,
        rms(&errors),
        1e3 * seconds / t.frames as f64
    ))
}

/// One-step errors (M_rms, mm) of the correction and the predictor on the built-in scene
/// of the dataset's name (its own seed: a sequence the fit never saw), frame by frame.
fn held_out(data: &ClothDataset, model: &InertialCorrection, frames: usize) -> Result<(), Box<dyn std::error::Error>> {
    let mut scene = weft_sim::ClothScene::builtin(&data.scene.name, data.rest.num_vertices() < 1000)?;
    scene.frames = frames;
    let mut sim = ClothSimulation::new(scene, None)?;
    let mut truth = vec![sim.integrator().positions().to_vec()];
    let mut controls = vec![Vec::new()];
    for _ in 0..frames {
        let f = sim.step()?;
        truth.push(f.positions);
        controls.push(f.controls);
    }
    let mm = |a: &[f64], b: &[f64]| {
        1e3 * (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
    };
    for m in 1..truth.len() {
        let p2 = &truth[m.saturating_sub(2)];
        let x = model.predict(p2, &truth[m - 1], &controls[m])?;
        let i: Vec<f64> = truth[m - 1].iter().zip(p2).map(|(a, b)| 2.0 * a - b).collect();
        println!(
            "  held-out frame {m}: corrected {:.3} mm, inertial {:.3} mm",
            mm(&x, &truth[m]),
            mm(&i, &truth[m])
        );
    }
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::args()
        .nth(1)
        .ok_or("usage: inertial_correction DATASET_DIR")?;
    let data = ClothDataset::load(dir.as_ref())?;
    let frames: usize = std::env::args().nth(2).map_or(Ok(usize::MAX), |f| f.parse())?;
    let clock = std::time::Instant::now();
    let model = InertialCorrection::fit(&data, &InertialCorrectionSettings::default())?;
    println!(
        "{}: fitted in {:.1} s; ridge {:?}",
        data.name,
        clock.elapsed().as_secs_f64(),
        model.ridge()
    );
    for s in model.validation_scores() {
        println!("  validation, ridge {:?}: {:.3} mm", s.ridge, s.one_step_mm);
    }
    let mut inertial = model.clone();
    inertial.disable_correction();
    for split in ["train", "validation", "test"] {
        let (c, i) = (
            model.one_step_errors(&data, split)?,
            inertial.one_step_errors(&data, split)?,
        );
        println!(
            "  {split}: one-step M_rms {:.3} mm corrected, {:.3} mm inertial",
            rms(&c),
            rms(&i)
        );
    }
    held_out(&data, &model, frames.min(60))?;
    let n = 3 * data.rest.num_vertices();
    for tau in [0.1, 0.3, 1.0] {
        let s = GuardSettings::millimetres(tau)?;
        println!(
            "  τ = {tau} mm, corrected: {}",
            replay(&data, frames, Box::new(model.clone()), s)?
        );
        println!(
            "  τ = {tau} mm, inertial:  {}",
            replay(&data, frames, Box::new(InertialPredictor::new(n)), s)?
        );
    }
    println!(
        "  truth's tolerance, corrected: {}",
        replay(&data, frames, Box::new(model.clone()), GuardSettings::ground_truth())?
    );
    println!(
        "  truth's tolerance, inertial:  {}",
        replay(
            &data,
            frames,
            Box::new(InertialPredictor::new(n)),
            GuardSettings::ground_truth()
        )?
    );
    Ok(())
}
