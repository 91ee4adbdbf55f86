//! Issue 71's gradient diagnostics on the quick sheet: each loss term's gradient on the
//! decoder against central differences of the term along that gradient and along a random
//! direction, and against candle's autograd (the reference kernels); λ_ephys calibrated
//! from the norms puts the terms at the ratio asked for when the model is built with it.

use candle_core::{Tensor, Var};
use weft_nn::Kernels;
use weft_nn::embed::{
    EmbedData, EmbedModel, EmbedTrainingSettings, FrameRef, calibrate_ephys, decoder_gradient_norms, decoder_gradients,
    decoder_parameters,
};
use weft_testkit::TestRng;

use super::base::{quick_sheet_dataset, small_embed_config};

/// Batches of 2 over 4 windows: the gradients of two batch means are combined.
fn config() -> EmbedTrainingSettings {
    EmbedTrainingSettings {
        batch: 2,
        ..small_embed_config()
    }
}

/// `(recon, vert, ephys)` of stage 1, each the mean over `windows`, through the training
/// path ([`EmbedModel::losses`]).
fn stage_1_terms(model: &EmbedModel, data: &EmbedData, windows: &[FrameRef]) -> [f64; 3] {
    let mut sum = [0.0; 3];
    for chunk in windows.chunks(model.config.batch) {
        let (_, t) = model.losses(data, chunk, 1, 1.0).unwrap();
        let share = chunk.len() as f64 / windows.len() as f64;
        for (s, v) in sum.iter_mut().zip([t.recon, t.vert, t.ephys]) {
            *s += share * v;
        }
    }
    sum
}

/// Moves every decoder weight by `step · direction` (laid out as the gradients are).
fn shift_decoder(vars: &[&Var], direction: &[f64], step: f64) {
    let mut at = 0;
    for var in vars {
        let n = var.elem_count();
        let now: Vec<f32> = var.as_tensor().flatten_all().unwrap().to_vec1().unwrap();
        let moved: Vec<f32> = now
            .iter()
            .zip(&direction[at..at + n])
            .map(|(w, d)| (f64::from(*w) + step * d) as f32)
            .collect();
        var.set(&Tensor::from_vec(moved, var.dims(), var.device()).unwrap())
            .unwrap();
        at += n;
    }
}

/// The central difference of the stage-1 terms along `direction` with step `h`.
fn slopes(model: &EmbedModel, data: &EmbedData, windows: &[FrameRef], direction: &[f64], h: f64) -> [f64; 3] {
    let vars = decoder_parameters(model);
    shift_decoder(&vars, direction, h);
    let plus = stage_1_terms(model, data, windows);
    shift_decoder(&vars, direction, -2.0 * h);
    let minus = stage_1_terms(model, data, windows);
    shift_decoder(&vars, direction, h);
    std::array::from_fn(|k| (plus[k] - minus[k]) / (2.0 * h))
}

#[test]
fn decoder_gradient_norms_are_the_slopes_of_the_terms_along_their_gradients() {
    let data = EmbedData::new(quick_sheet_dataset(20)).unwrap();
    let windows = &data.train_windows[..4];
    let model = EmbedModel::new(config(), &data).unwrap();
    let grads = decoder_gradients(&model, &data, windows, 1).unwrap();
    let names: Vec<&str> = grads.iter().map(|g| g.term).collect();
    assert_eq!(names, ["recon", "vert", "ephys"]);
    let values = stage_1_terms(&model, &data, windows);
    let mut rng = TestRng::new(71);
    let random: Vec<f64> = (0..grads[0].gradient.len()).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let random_norm = random.iter().map(|x| x * x).sum::<f64>().sqrt();
    let random: Vec<f64> = random.iter().map(|x| x / random_norm).collect();
    let along_random = slopes(&model, &data, windows, &random, 1e-2);
    let fused = decoder_gradient_norms(&model, &data, windows, 1).unwrap();
    // The decoder of the quick sheet (81 vertices, 9 channels, latent 8, one convolution):
    // `decoder.fc` (8 × 729 + 729) and `decoder.conv0` (9 × 9 twice, + 9).
    assert_eq!(fused.parameters, 8 * 729 + 729 + 2 * 81 + 9);
    for (k, g) in grads.iter().enumerate() {
        weft_testkit::assert_close!(g.value, values[k], rtol = 1e-6, atol = 0.0);
        let norm = g.gradient.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!(norm > 0.0, "{}: no gradient", g.term);
        // Along the unit gradient the term rises at the gradient's norm.
        let unit: Vec<f64> = g.gradient.iter().map(|x| x / norm).collect();
        let slope = slopes(&model, &data, windows, &unit, 1e-2)[k];
        weft_testkit::assert_close!(slope, fused.terms[k].norm, rtol = 1e-2, atol = 0.0);
        // Along a random unit direction, at the projection of the gradient on it.
        let dot: f64 = g.gradient.iter().zip(&random).map(|(a, b)| a * b).sum();
        weft_testkit::assert_close!(along_random[k], dot, rtol = 2e-2, atol = 2e-2 * norm / 10.0);
    }
    // candle's autograd through the layers (the reference kernels) gives the same norms.
    let reference = EmbedModel::new(
        EmbedTrainingSettings {
            kernels: Kernels::Autograd,
            ..config()
        },
        &data,
    )
    .unwrap();
    let autograd = decoder_gradient_norms(&reference, &data, windows, 1).unwrap();
    for (a, b) in fused.terms.iter().zip(&autograd.terms) {
        weft_testkit::assert_close!(a.norm, b.norm, rtol = 1e-3, atol = 0.0);
    }
    // L_sim never reaches the decoder; stage 2's L_mphys does, through ACAP⁻¹ ∘ D.
    let stage_2 = decoder_gradient_norms(&model, &data, windows, 2).unwrap();
    assert_eq!(stage_2.term("sim").unwrap().norm, 0.0);
    assert!(stage_2.term("mphys").unwrap().norm > 0.0);
    assert!(decoder_gradients(&model, &data, &[], 1).is_err());
    assert!(decoder_gradients(&model, &data, windows, 4).is_err());
}

#[test]
fn the_calibrated_ephys_weight_puts_the_gradients_at_the_ratio_asked_for() {
    let data = EmbedData::new(quick_sheet_dataset(20)).unwrap();
    let windows = &data.train_windows[..4];
    // A no-pb model: L_ephys is measured though its weight is 0.
    let mut no_pb = config();
    no_pb.weights.ephys = 0.0;
    no_pb.weights.mphys = 0.0;
    let model = EmbedModel::new(no_pb.clone(), &data).unwrap();
    let before = decoder_gradient_norms(&model, &data, windows, 1).unwrap();
    assert_eq!(before.term("ephys").unwrap().weighted_norm, 0.0);
    let ratio = 0.25;
    let c = calibrate_ephys(&before, ratio).unwrap();
    let dominant = ["recon", "vert"]
        .into_iter()
        .max_by(|a, b| {
            let w = |t: &str| before.term(t).unwrap().weighted_norm;
            w(a).total_cmp(&w(b))
        })
        .unwrap();
    assert_eq!(c.dominant, dominant);
    // Measured again on the model built with the calibrated weight (same seed, same
    // weights): λ_ephys ‖∇L_ephys‖ is `ratio` times the dominating term's.
    let mut calibrated = no_pb;
    calibrated.weights.ephys = c.ephys_weight;
    let model = EmbedModel::new(calibrated, &data).unwrap();
    let after = decoder_gradient_norms(&model, &data, windows, 1).unwrap();
    let ephys = after.term("ephys").unwrap().weighted_norm;
    let top = after
        .terms
        .iter()
        .filter(|t| t.term != "ephys")
        .map(|t| t.weighted_norm)
        .fold(0.0, f64::max);
    weft_testkit::assert_close!(ephys / top, ratio, rtol = 1e-9, atol = 0.0);
    // The calibration is a fixed point: calibrating again keeps the weight.
    let again = calibrate_ephys(&after, ratio).unwrap();
    weft_testkit::assert_close!(again.ephys_weight, c.ephys_weight, rtol = 1e-9, atol = 0.0);
    assert!(calibrate_ephys(&after, 0.0).is_err());
    assert!(calibrate_ephys(&after, f64::NAN).is_err());
    let stage_2 = decoder_gradient_norms(&model, &data, windows, 2).unwrap();
    assert!(calibrate_ephys(&stage_2, ratio).is_err(), "stage 2 has no L_ephys");
}
