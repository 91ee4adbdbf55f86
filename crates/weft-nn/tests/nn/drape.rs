//! Geng et al.'s pose → cloth training with the projection layers (weft_nn::drape) on the
//! quick drape scene: the gradient of the whole training loss into a learned μ (global
//! and per vertex) against finite differences, and short training runs in which the
//! trained postprocess lowers the training loss.

use std::sync::Arc;

use candle_core::{Device, Tensor};
use weft_nn::adam::AdamSettings;
use weft_nn::drape::{DrapeModel, DrapeNet, DrapeNetSettings, DrapeTensors, DrapeTraining, Mu, Postprocess, loss};
use weft_nn::ops::{InextensibilityProjection, QuasistaticProjection};
use weft_nn::params::ParamStore;
use weft_nn::trainer::{Schedule, Silent, Trainer, TrainerSettings, TrainingState};
use weft_proj::{InextensibilityLayer, QuasistaticLayer, QuasistaticParams, SocpSettings};
use weft_sim::rng::SplitMix64;
use weft_sim::scenes::drape::{Drape, DrapeParams};
use weft_sim::scenes::soft_tissue::ArmPose;

/// Trains `model` through the trainer for `epochs` in a fresh directory.
#[allow(clippy::too_many_arguments)]
fn fit(
    model: &DrapeModel,
    net: (&ParamStore, AdamSettings),
    mu: Option<(&ParamStore, AdamSettings)>,
    train: &DrapeTensors,
    validation: &DrapeTensors,
    batch: usize,
    epochs: usize,
    seed: u64,
) -> weft_nn::Result<TrainingState> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static N: AtomicUsize = AtomicUsize::new(0);
    let dir = std::env::temp_dir().join(format!(
        "weft-drape-test-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::SeqCst)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    let config = TrainerSettings {
        epochs,
        batch,
        seed,
        schedule: Schedule::default(),
    };
    let mut t = DrapeTraining::new(model, net, mu, train, validation, batch);
    Trainer::new("drape-test", config).run(&dir, &mut t, &mut Silent)
}

/// Six solved examples of the quick scene (the converged ones of the first draws).
fn examples() -> (Drape, DrapeTensors) {
    let d = Drape::new(DrapeParams::quick()).unwrap();
    let mut rng = SplitMix64::new(3);
    let (mut pose, mut guess, mut truth) = (Vec::new(), Vec::new(), Vec::new());
    while pose.len() < 6 * weft_nn::drape::POSE_ANGLES {
        if let Ok(e) = d.solve(&ArmPose::sample(&mut rng)) {
            pose.extend(e.pose.angles());
            guess.extend(e.guess);
            truth.extend(e.truth);
        }
    }
    let v = d.sleeve().num_vertices();
    let t = DrapeTensors::new(&pose, &guess, &truth, v, &Device::Cpu).unwrap();
    (d, t)
}

fn quasistatic(d: &Drape) -> QuasistaticProjection {
    QuasistaticProjection::new(Arc::new(
        QuasistaticLayer::new(d.sleeve(), QuasistaticParams::default()).unwrap(),
    ))
}

#[test]
fn the_mu_gradient_of_the_training_loss_matches_finite_differences() {
    let (d, data) = examples();
    let v = d.sleeve().num_vertices();
    for per_vertex in [None, Some(v)] {
        let mut net_params = ParamStore::new(&Device::Cpu, 5);
        let net = DrapeNet::new(&mut net_params, &DrapeNetSettings::default(), v).unwrap();
        let mut mu_params = ParamStore::new(&Device::Cpu, 6);
        let mu = Mu::learned(&mut mu_params, 0.1, per_vertex).unwrap();
        let Mu::Learned(log_mu) = &mu else { unreachable!() };
        let log_mu = log_mu.clone();
        let model = DrapeModel {
            net,
            post: Postprocess::Quasistatic {
                op: quasistatic(&d),
                mu,
            },
        };
        let l = loss(&model.predict(&data.pose, &data.guess).unwrap(), &data.truth).unwrap();
        let grads = l.backward().unwrap();
        let g: Vec<f32> = grads.get(&log_mu).unwrap().to_vec1().unwrap();
        // A direction in log μ: all ones (global) or alternating signs (per vertex).
        let dir: Vec<f32> = (0..g.len()).map(|i| if i % 3 == 2 { -1.0 } else { 1.0 }).collect();
        let analytic: f64 = g.iter().zip(&dir).map(|(a, b)| f64::from(a * b)).sum();
        let var = &mu_params.vars()["mu.log"];
        let base: Vec<f32> = log_mu.to_vec1().unwrap();
        let at = |h: f32| -> f64 {
            let moved: Vec<f32> = base.iter().zip(&dir).map(|(b, d)| b + h * d).collect();
            var.set(&Tensor::from_vec(moved, base.len(), &Device::Cpu).unwrap())
                .unwrap();
            let l = loss(&model.predict(&data.pose, &data.guess).unwrap(), &data.truth).unwrap();
            f64::from(l.to_scalar::<f32>().unwrap())
        };
        let h = 0.02;
        let fd = (at(h) - at(-h)) / (2.0 * f64::from(h));
        assert!(analytic.abs() > 1e-3, "the μ gradient is zero: {analytic}");
        assert!(
            (fd - analytic).abs() <= 0.02 * analytic.abs(),
            "per vertex {}: analytic {analytic}, finite differences {fd}",
            per_vertex.is_some()
        );
    }
}

/// The epoch report's μ-gradient statistics are the per-batch gradients of the loss in
/// log μ: with the parameters held (a vanishing learning rate), one batch of every example
/// reports the whole loss's gradient (checked against finite differences) and no spread,
/// and two equal batches report the same mean (the loss is a mean over examples).
#[test]
fn the_epoch_reports_the_per_batch_mu_gradient() {
    let (d, data) = examples();
    let v = d.sleeve().num_vertices();
    let mut net_params = ParamStore::new(&Device::Cpu, 5);
    let net = DrapeNet::new(&mut net_params, &DrapeNetSettings::default(), v).unwrap();
    let mut mu_params = ParamStore::new(&Device::Cpu, 6);
    let mu = Mu::learned(&mut mu_params, 0.1, None).unwrap();
    let model = DrapeModel {
        net,
        post: Postprocess::Quasistatic {
            op: quasistatic(&d),
            mu,
        },
    };
    let held = AdamSettings {
        learning_rate: 1e-30,
        ..AdamSettings::default()
    };
    // One epoch at a learning rate too small to move anything: the record holds the
    // per-batch gradient of the loss in log μ, its mean and spread over the batches.
    let epoch = |batch: usize| {
        let state = fit(
            &model,
            (&net_params, held),
            Some((&mu_params, held)),
            &data,
            &data,
            batch,
            1,
            0,
        )
        .unwrap();
        let e = &state.history[0].extra;
        (e["mu_gradient_mean"], e["mu_gradient_sd"])
    };
    let whole = epoch(data.len());
    let halves = epoch(data.len() / 2);
    let var = &mu_params.vars()["mu.log"];
    let base: f32 = var.as_tensor().to_vec1::<f32>().unwrap()[0];
    let at = |h: f32| -> f64 {
        var.set(&Tensor::new(&[base + h], &Device::Cpu).unwrap()).unwrap();
        let l = loss(&model.predict(&data.pose, &data.guess).unwrap(), &data.truth).unwrap();
        f64::from(l.to_scalar::<f32>().unwrap())
    };
    let h = 0.02;
    let fd = (at(h) - at(-h)) / (2.0 * f64::from(h));
    assert_eq!(whole.1, 0.0, "one batch has no spread");
    assert!(fd.abs() > 1e-3, "the μ gradient is zero: {fd}");
    assert!(
        (whole.0 - fd).abs() <= 0.02 * fd.abs(),
        "one batch: {whole:?}, finite differences {fd}"
    );
    assert!(halves.1 > 0.0, "two batches differ");
    assert!(
        (halves.0 - whole.0).abs() <= 1e-3 * whole.0.abs(),
        "two batches {halves:?} against one {whole:?}"
    );
}

/// Trains the network alone for `epochs`, then with `post` for as many, returning the
/// training loss with the postprocess before and after its training.
fn pretrain_then_train(d: &Drape, data: &DrapeTensors, post: impl Fn(&mut ParamStore) -> Postprocess) -> (f64, f64) {
    let v = d.sleeve().num_vertices();
    let mut net_params = ParamStore::new(&Device::Cpu, 9);
    let net = DrapeNet::new(&mut net_params, &DrapeNetSettings::default(), v).unwrap();
    let settings = AdamSettings {
        learning_rate: 1e-3,
        ..AdamSettings::default()
    };
    let mut model = DrapeModel {
        net,
        post: Postprocess::None,
    };
    fit(&model, (&net_params, settings), None, data, data, 3, 30, 1).unwrap();
    let mut mu_params = ParamStore::new(&Device::Cpu, 10);
    model.post = post(&mut mu_params);
    let eval = |m: &DrapeModel| {
        f64::from(
            loss(&m.predict(&data.pose, &data.guess).unwrap(), &data.truth)
                .unwrap()
                .to_scalar::<f32>()
                .unwrap(),
        )
    };
    let before = eval(&model);
    fit(&model, (&net_params, settings), None, data, data, 3, 8, 2).unwrap();
    (before, eval(&model))
}

#[test]
fn training_through_the_quasistatic_layer_lowers_the_training_loss() {
    let (d, data) = examples();
    let (before, after) = pretrain_then_train(&d, &data, |_| Postprocess::Quasistatic {
        op: quasistatic(&d),
        mu: Mu::Fixed(0.1),
    });
    assert!(after < 0.9 * before, "training loss {before} → {after} mm²");
}

#[test]
fn training_through_the_inextensibility_layer_lowers_the_training_loss() {
    let (d, data) = examples();
    let layer = Arc::new(InextensibilityLayer::new(d.sleeve(), 0.1, SocpSettings::default()).unwrap());
    let (before, after) = pretrain_then_train(&d, &data, |_| {
        Postprocess::Inextensibility(InextensibilityProjection::new(layer.clone()))
    });
    assert!(after < 0.9 * before, "training loss {before} → {after} mm²");
}

#[test]
fn a_failing_example_is_left_out_of_predictions_and_its_batch_skipped_in_training() {
    let (d, data) = examples();
    let v = d.sleeve().num_vertices();
    // Example 1's pose overflows the network to a non-finite prediction, which the
    // quasistatic op refuses; the others are fine.
    let mut pose: Vec<f64> = data.poses().unwrap();
    let k = weft_nn::drape::POSE_ANGLES;
    pose[k..2 * k].copy_from_slice(&[1e38, -1e38, 1e38, -1e38]);
    let guess: Vec<f64> = data
        .guess
        .flatten_all()
        .unwrap()
        .to_dtype(candle_core::DType::F64)
        .unwrap()
        .to_vec1()
        .unwrap();
    let truth: Vec<f64> = data.truths().unwrap().concat();
    let bad = DrapeTensors::new(&pose, &guess, &truth, v, &Device::Cpu).unwrap();
    let mut net_params = ParamStore::new(&Device::Cpu, 21);
    let net = DrapeNet::new(&mut net_params, &DrapeNetSettings::default(), v).unwrap();
    let model = DrapeModel {
        net,
        post: Postprocess::Quasistatic {
            op: quasistatic(&d),
            mu: Mu::Fixed(0.1),
        },
    };
    let each = weft_nn::drape::predict_each(&model, &bad, 4).unwrap();
    assert_eq!(each.len(), bad.len());
    assert!(each[1].is_err(), "the overflowing example must fail");
    assert!(each.iter().enumerate().all(|(i, r)| i == 1 || r.is_ok()));
    // Training one example per batch: that batch is skipped and counted, the rest train.
    let settings = AdamSettings::default();
    let state = fit(&model, (&net_params, settings), None, &bad, &data, 1, 1, 0).unwrap();
    let (skipped, first) = state.skipped();
    assert_eq!(skipped, 1);
    assert!(first.is_some() && state.history[0].loss.is_finite());
    // Without a postprocess the same example is a non-finite loss: an error, not a skip.
    let plain = DrapeModel {
        net: model.net.clone(),
        post: Postprocess::None,
    };
    let e = fit(&plain, (&net_params, settings), None, &bad, &data, 1, 1, 0).unwrap_err();
    assert!(e.to_string().contains("training loss"), "{e}");
}

/// The per-epoch validation pass warm-starts each layer solve from the same example's
/// previous solution (under other weights); model selection relies on it reaching the
/// cold solve's answer.
#[test]
fn keyed_predictions_started_from_another_models_solutions_match_cold_ones() {
    let (d, data) = examples();
    let v = d.sleeve().num_vertices();
    let layer = Arc::new(InextensibilityLayer::new(d.sleeve(), 0.1, SocpSettings::default()).unwrap());
    let posts = [
        Postprocess::Quasistatic {
            op: quasistatic(&d),
            mu: Mu::Fixed(0.1),
        },
        Postprocess::Inextensibility(InextensibilityProjection::new(layer)),
    ];
    for post in posts {
        // Two networks sharing one layer op, hence one warm-start store.
        let model = |seed| {
            let mut params = ParamStore::new(&Device::Cpu, seed);
            DrapeModel {
                net: DrapeNet::new(&mut params, &DrapeNetSettings::default(), v).unwrap(),
                post: post.clone(),
            }
        };
        let (a, b) = (model(31), model(32));
        let flat = |r: Vec<Result<Vec<f64>, String>>| -> Vec<f64> { r.into_iter().flat_map(|x| x.unwrap()).collect() };
        let max_diff = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(p, q)| (p - q).abs()).fold(0.0, f64::max);
        let a_warm = flat(weft_nn::drape::predict_each_keyed(&a, &data, 4, 100).unwrap());
        let b_cold = flat(weft_nn::drape::predict_each(&b, &data, 4).unwrap());
        // `b` starts from `a`'s solutions, which are far from its own answers.
        let b_warm = flat(weft_nn::drape::predict_each_keyed(&b, &data, 4, 100).unwrap());
        let apart = max_diff(&a_warm, &b_cold);
        let warm_vs_cold = max_diff(&b_warm, &b_cold);
        assert!(
            apart > 1e-3,
            "the two networks predict nearly the same cloth ({apart} m)"
        );
        assert!(
            warm_vs_cold < 1e-5,
            "warm-started solves differ from cold ones by {warm_vs_cold} m"
        );
    }
}
