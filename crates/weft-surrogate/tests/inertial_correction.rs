//! The inertial correction (`weft_surrogate::inertial_correction`, docs/GUARD.md): an exact fit
//! where the residual is linear in the features, the model directory's round trip, and
//! its use under weft-sim's guard with typed errors for mismatches.

use weft_data::{ClothDataset, ClothSequence, is_validation_frame};
use weft_sim::guard::{Guard, GuardSettings, StepInput, Surrogate};
use weft_sim::rng::SplitMix64;
use weft_sim::{ClothScene, Error as SimError};
use weft_surrogate::inertial_correction::{InertialCorrection, InertialCorrectionSettings};

fn quick_scene() -> ClothScene {
    ClothScene::builtin("sheet-ms", true).unwrap()
}

/// A dataset of the quick sheet whose frames follow a linear recurrence in two modes
/// that leave the grasp still, from rest (`a_{−1} = a_0`): `a_m = 2a_{m−1} − a_{m−2} + Δ_m` with
/// `Δ_m = −κ a_{m−1} − γ (a_{m−1} − a_{m−2}) + g`, positions `rest + Φ a`. The inertial
/// residual `Φ Δ_m` is then exactly linear in the state and velocity codes plus a bias.
fn linear_dataset(sequences: usize, frames: usize) -> ClothDataset {
    let mut data = ClothDataset::simulate("linear", quick_scene(), 1).unwrap();
    let rest: Vec<f64> = data.sequences[0].frame(0).to_vec();
    let n = rest.len();
    let grasp = data.grasp.clone();
    let mut rng = SplitMix64::new(5);
    let modes: Vec<Vec<f64>> = (0..2)
        .map(|_| {
            (0..n)
                .map(|i| {
                    if grasp.contains(&(i / 3)) {
                        0.0
                    } else {
                        0.01 * (2.0 * rng.unit() - 1.0)
                    }
                })
                .collect()
        })
        .collect();
    let (kappa, gamma, g) = ([0.05, 0.12], [0.02, 0.03], [-0.01, 0.004]);
    let controls: Vec<f64> = grasp.iter().flat_map(|&v| rest[3 * v..3 * v + 3].to_vec()).collect();
    data.sequences = (0..sequences)
        .map(|s| {
            // Frame 0 at rest (`a_{−1} = a_0`), as the guard's first step sees it.
            let mut a = vec![[0.3 * s as f64 - 0.4, 0.5 - 0.2 * s as f64]];
            while a.len() < frames {
                let (a1, a2) = (a[a.len() - 1], a[a.len().saturating_sub(2)]);
                a.push(std::array::from_fn(|k| {
                    2.0 * a1[k] - a2[k] - kappa[k] * a1[k] - gamma[k] * (a1[k] - a2[k]) + g[k]
                }));
            }
            let positions: Vec<f64> = a
                .iter()
                .flat_map(|c| {
                    (0..n)
                        .map(|i| rest[i] + c[0] * modes[0][i] + c[1] * modes[1][i])
                        .collect::<Vec<_>>()
                })
                .collect();
            ClothSequence::new(
                s,
                positions,
                controls.repeat(frames),
                vec![0; frames],
                n / 3,
                grasp.len(),
            )
            .unwrap()
        })
        .collect();
    data
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|e| e * e).sum::<f64>() / v.len() as f64).sqrt()
}

#[test]
fn a_residual_linear_in_the_features_is_fitted_exactly() {
    let data = linear_dataset(3, 40);
    let model = InertialCorrection::fit(&data, &InertialCorrectionSettings::default()).unwrap();
    let mut inertial = model.clone();
    inertial.disable_correction();
    let before = rms(&inertial.one_step_errors(&data, "test").unwrap());
    let after = rms(&model.one_step_errors(&data, "test").unwrap());
    assert!(before > 0.05, "the recurrence moves: inertial error {before} mm");
    assert!(model.ridge().is_some(), "a correction is chosen");
    assert!(
        after < 1e-3 * before,
        "test one-step error {after} mm against the predictor's {before} mm"
    );
    // The residuals lie in two modes, which the correction basis spans: no floor.
    let floor = rms(&model.basis_floor_errors(&data, "test").unwrap());
    assert!(floor < 1e-6 * before, "basis floor {floor} mm");
    // "No correction" is scored first, so the kept model is never worse on validation.
    let scores = model.validation_scores();
    assert_eq!(scores[0].ridge, None);
    let kept = scores.iter().find(|s| s.ridge == model.ridge()).unwrap();
    assert!(scores.iter().all(|s| kept.one_step_mm <= s.one_step_mm));
}

#[test]
fn the_model_directory_round_trips_and_refuses_another_kind() {
    let data = linear_dataset(3, 40);
    let model = InertialCorrection::fit(&data, &InertialCorrectionSettings::default()).unwrap();
    let dir = std::env::temp_dir().join(format!("weft-ic-{}", std::process::id()));
    model.save(&dir).unwrap();
    let loaded = InertialCorrection::load(&dir).unwrap();
    let seq = &data.sequences[1];
    let (a, b) = (
        model.predict(seq.frame(8), seq.frame(9), seq.control(10)).unwrap(),
        loaded.predict(seq.frame(8), seq.frame(9), seq.control(10)).unwrap(),
    );
    assert_eq!(a, b);
    // Another model kind's directory is refused by name.
    std::fs::write(dir.join("config.json"), r#"{"material": "stvk"}"#).unwrap();
    let err = InertialCorrection::load(&dir).unwrap_err().to_string();
    assert!(err.contains("nnwarp"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn under_the_guard_a_mismatch_is_a_typed_error_and_proposals_are_checked() {
    let scene = quick_scene();
    let data = ClothDataset::simulate("sheet-ms", scene.clone(), 60).unwrap();
    assert!((0..60).any(is_validation_frame));
    let model = InertialCorrection::fit(&data, &InertialCorrectionSettings::default()).unwrap();
    let sim = weft_sim::ClothSimulation::new(scene.clone(), None).unwrap();
    // Another scene's name: refused, naming both.
    let err = Guard::new(
        sim.integrator(),
        "sheet-fem",
        Box::new(model.clone()),
        GuardSettings::ground_truth(),
    )
    .unwrap_err();
    assert!(
        matches!(err, SimError::SurrogateMismatch { what: "scene", .. }),
        "{err}"
    );
    // Controls without the grasp: the surrogate's own error, wrapped with its name.
    let mut guard = Guard::new(
        sim.integrator(),
        &scene.name,
        Box::new(model.clone()),
        GuardSettings::ground_truth(),
    )
    .unwrap();
    let mut integrator = sim.into_integrator();
    let err = guard.step(&mut integrator, 1, &[], None).unwrap_err();
    assert!(matches!(err, SimError::Surrogate { .. }), "{err}");
    // On the data it was fitted to, one step from the truth's history: its proposal is
    // closer to the truth than the inertial predictor's on the validation frames.
    let seq = &data.sequences[0];
    let mut model = model;
    let (mut corrected, mut inertial) = (Vec::new(), Vec::new());
    for m in (2..60).filter(|&m| is_validation_frame(m)) {
        let prescribed = data.prescribed_at(0, m);
        let input = StepInput {
            frame: m,
            dt: scene.dt,
            current: seq.frame(m - 1),
            previous: seq.frame(m - 2),
            prescribed: &prescribed,
        };
        let x = model.propose(&input).unwrap();
        let guess: Vec<f64> = input
            .current
            .iter()
            .zip(input.previous)
            .map(|(c, p)| 2.0 * c - p)
            .collect();
        let err = |y: &[f64]| y.iter().zip(seq.frame(m)).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        corrected.push(err(&x));
        inertial.push(err(&guess));
    }
    assert!(corrected.iter().sum::<f64>() < inertial.iter().sum::<f64>());
}
