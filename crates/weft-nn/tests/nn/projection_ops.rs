//! The projection layers as candle ops (Geng et al. §5): the quasistatic op's gradients
//! into the prediction and into μ, global and per vertex, against finite differences of
//! the op itself.

use std::sync::Arc;

use candle_core::{Device, Tensor, Var};
use weft_nn::ops::QuasistaticProjection;
use weft_proj::{QuasistaticLayer, QuasistaticParams};
use weft_testkit::TestRng;

#[test]
fn the_quasistatic_op_has_the_gradients_of_its_finite_differences() {
    let rest = weft_mesh::generators::sheet(4, 1.0).unwrap();
    let v = rest.num_vertices();
    let layer = Arc::new(QuasistaticLayer::new(&rest, QuasistaticParams::default()).unwrap());
    let op = QuasistaticProjection::new(layer);
    let mut rng = TestRng::new(11);
    // Two predictions: the rest sheet stretched and bumped, with noise.
    let pred: Vec<f32> = (0..2)
        .flat_map(|b| {
            let rest = &rest;
            let noise: Vec<f64> = (0..3 * v).map(|_| rng.uniform(-0.02, 0.02)).collect();
            rest.positions().iter().enumerate().flat_map(move |(i, p)| {
                let s = 1.1 + 0.05 * b as f64;
                [
                    (s * p.x + noise[3 * i]) as f32,
                    (p.y + noise[3 * i + 1]) as f32,
                    (0.1 * (3.0 * p.x).sin() + noise[3 * i + 2]) as f32,
                ]
            })
        })
        .collect();
    let weights: Vec<f32> = (0..2 * 3 * v).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
    let w = Tensor::from_vec(weights, (2, v, 3), &Device::Cpu).unwrap();
    for mu0 in [vec![0.1f32], (0..v).map(|i| 0.05 + 0.01 * i as f32).collect()] {
        let x = Var::from_tensor(&Tensor::from_vec(pred.clone(), (2, v, 3), &Device::Cpu).unwrap()).unwrap();
        let mu = Var::from_tensor(&Tensor::from_vec(mu0.clone(), mu0.len(), &Device::Cpu).unwrap()).unwrap();
        let loss = |x: &Tensor, mu: &Tensor| -> f64 {
            (op.apply(x, mu).unwrap() * &w)
                .unwrap()
                .sum_all()
                .unwrap()
                .to_scalar::<f32>()
                .unwrap() as f64
        };
        let out = op.apply(x.as_tensor(), mu.as_tensor()).unwrap();
        assert_eq!(out.dims(), &[2, v, 3]);
        let grads = (out * &w).unwrap().sum_all().unwrap().backward().unwrap();
        let gx: Vec<f32> = grads
            .get(x.as_tensor())
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let gmu: Vec<f32> = grads
            .get(mu.as_tensor())
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let scale = gx.iter().fold(0.0f32, |m, g| m.max(g.abs())) as f64;
        assert!(scale > 0.0);
        // Central differences of the op in f32: step 1e-3 m, tolerance 3 % of the largest entry.
        for k in [0, 7, 3 * v + 4, 6 * v - 1] {
            let at = |d: f32| {
                let mut p = pred.clone();
                p[k] += d;
                loss(&Tensor::from_vec(p, (2, v, 3), &Device::Cpu).unwrap(), mu.as_tensor())
            };
            let fd = (at(1e-3) - at(-1e-3)) / 2e-3;
            assert!(
                (fd - gx[k] as f64).abs() <= 0.03 * scale,
                "prediction entry {k}: fd {fd} vs {}",
                gx[k]
            );
        }
        let mu_scale = gmu.iter().fold(0.0f32, |m, g| m.max(g.abs())) as f64;
        for k in [0, mu0.len() - 1] {
            let h = 1e-2 * mu0[k];
            let at = |d: f32| {
                let mut m = mu0.clone();
                m[k] += d;
                loss(
                    x.as_tensor(),
                    &Tensor::from_vec(m.clone(), m.len(), &Device::Cpu).unwrap(),
                )
            };
            let fd = (at(h) - at(-h)) / (2.0 * h as f64);
            assert!(
                (fd - gmu[k] as f64).abs() <= 0.03 * mu_scale.max(fd.abs()),
                "mu entry {k} of {}: fd {fd} vs {}",
                mu0.len(),
                gmu[k]
            );
        }
    }
    // A μ of the wrong length and a prediction of the wrong size are typed errors.
    let x = Tensor::from_vec(pred.clone(), (2, v, 3), &Device::Cpu).unwrap();
    assert!(
        op.apply(&x, &Tensor::from_vec(vec![0.1f32; 3], 3, &Device::Cpu).unwrap())
            .is_err()
    );
    assert!(
        op.apply(
            &x.narrow(1, 0, v - 1).unwrap(),
            &Tensor::from_vec(vec![0.1f32], 1, &Device::Cpu).unwrap()
        )
        .is_err()
    );
}

#[test]
fn the_inextensibility_op_has_the_gradient_of_its_finite_differences() {
    use weft_nn::ops::InextensibilityProjection;
    use weft_proj::{InextensibilityLayer, SocpSettings};
    let rest = weft_mesh::generators::sheet(4, 1.0).unwrap();
    let v = rest.num_vertices();
    let op = InextensibilityProjection::new(Arc::new(
        InextensibilityLayer::new(&rest, 0.05, SocpSettings::default()).unwrap(),
    ));
    let mut rng = TestRng::new(13);
    // Stretched 15 % along x, so that the bound is active on many edges.
    let pred: Vec<f32> = rest
        .positions()
        .iter()
        .flat_map(|p| {
            [
                (1.15 * p.x + rng.uniform(-0.01, 0.01)) as f32,
                (p.y + rng.uniform(-0.01, 0.01)) as f32,
                (0.05 * (2.0 * p.y).cos() + rng.uniform(-0.01, 0.01)) as f32,
            ]
        })
        .collect();
    let w = Tensor::from_vec(
        (0..3 * v).map(|_| rng.uniform(-1.0, 1.0) as f32).collect::<Vec<_>>(),
        (1, v, 3),
        &Device::Cpu,
    )
    .unwrap();
    let loss = |x: &Tensor| -> f64 {
        (op.apply(x).unwrap() * &w)
            .unwrap()
            .sum_all()
            .unwrap()
            .to_scalar::<f32>()
            .unwrap() as f64
    };
    let x = Var::from_tensor(&Tensor::from_vec(pred.clone(), (1, v, 3), &Device::Cpu).unwrap()).unwrap();
    let out = op.apply(x.as_tensor()).unwrap();
    // The projection moved the prediction: the bound was active.
    let moved = (&out - x.as_tensor())
        .unwrap()
        .abs()
        .unwrap()
        .max_all()
        .unwrap()
        .to_scalar::<f32>()
        .unwrap();
    assert!(moved > 1e-3, "{moved}");
    let grads = (out * &w).unwrap().sum_all().unwrap().backward().unwrap();
    let g: Vec<f32> = grads
        .get(x.as_tensor())
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    let scale = g.iter().fold(0.0f32, |m, v| m.max(v.abs())) as f64;
    for k in [0, 5, 3 * v / 2, 3 * v - 1] {
        let at = |d: f32| {
            let mut p = pred.clone();
            p[k] += d;
            loss(&Tensor::from_vec(p, (1, v, 3), &Device::Cpu).unwrap())
        };
        let fd = (at(1e-3) - at(-1e-3)) / 2e-3;
        assert!(
            (fd - g[k] as f64).abs() <= 0.05 * scale,
            "entry {k}: fd {fd} vs {}",
            g[k]
        );
    }
    assert!(
        op.apply(&Tensor::zeros((1, v + 1, 3), candle_core::DType::F32, &Device::Cpu).unwrap())
            .is_err()
    );
}

#[test]
fn keyed_calls_warm_start_from_the_previous_equilibrium_and_agree_with_cold_ones() {
    let rest = weft_mesh::generators::sheet(6, 1.0).unwrap();
    let v = rest.num_vertices();
    let layer = Arc::new(QuasistaticLayer::new(&rest, QuasistaticParams::default()).unwrap());
    let op = QuasistaticProjection::new(layer);
    let pred = |s: f32| -> Tensor {
        let x: Vec<f32> = rest
            .positions()
            .iter()
            .flat_map(|p| [s * p.x as f32, p.y as f32, 0.05 * (3.0 * p.x as f32).sin()])
            .collect();
        Tensor::from_vec(x, (1, v, 3), &Device::Cpu).unwrap()
    };
    let mu = Tensor::new(&[0.1f32], &Device::Cpu).unwrap();
    // First call remembers example 7's equilibrium; the second starts from it.
    op.apply_keyed(&pred(1.2), &mu, &[7]).unwrap();
    let warm = op.apply_keyed(&pred(1.25), &mu, &[7]).unwrap();
    let cold = op.apply(&pred(1.25), &mu).unwrap();
    let diff = (warm - cold)
        .unwrap()
        .abs()
        .unwrap()
        .max_all()
        .unwrap()
        .to_scalar::<f32>()
        .unwrap();
    assert!(diff < 1e-6, "warm and cold equilibria differ by {diff} m");
    assert!(op.apply_keyed(&pred(1.2), &mu, &[1, 2]).is_err(), "one key per example");
}
