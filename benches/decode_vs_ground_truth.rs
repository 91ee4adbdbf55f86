//! The learned simulator's hot path against the ground truth it replaces, in one run:
//! one implicit-Euler frame of `sheet-ms` (4225 vertices) versus ACAP encode and ACAP⁻¹
//! decode of that same frame (Tan et al.: the latent simulator must decode every frame,
//! so decode must be a small fraction of a ground-truth frame).

use std::cell::RefCell;

use criterion::{Criterion, criterion_group, criterion_main};
use weft_acap::{AcapFeatures, AcapSettings, PoissonPseudoInverse};
use weft_mesh::unflatten;
use weft_sim::{ClothScene, ClothSimulation};

fn decode_vs_ground_truth(c: &mut Criterion) {
    let sim = RefCell::new(ClothSimulation::new(ClothScene::builtin("sheet-ms", false).unwrap(), None).unwrap());
    for _ in 0..5 {
        sim.borrow_mut().step().unwrap();
    }
    let frame = unflatten(sim.borrow().integrator().positions());
    let pins = sim.borrow().grasp_vertices().to_vec();
    let features = AcapFeatures::new(sim.borrow().mesh(), AcapSettings::default()).unwrap();
    let inverse = PoissonPseudoInverse::new(&features, &pins).unwrap();
    let encoded = features.encode(&frame).unwrap();
    let pin_positions: Vec<_> = pins.iter().map(|&i| frame[i]).collect();

    let mut group = c.benchmark_group("sheet-ms-4225");
    group.sample_size(10);
    group.bench_function("ground-truth frame (implicit Euler)", |b| {
        b.iter(|| sim.borrow_mut().step().unwrap())
    });
    group.bench_function("acap encode", |b| b.iter(|| features.encode(&frame).unwrap()));
    group.bench_function("acap decode", |b| {
        b.iter(|| inverse.decode(&encoded, &pin_positions).unwrap())
    });
    group.finish();
}

criterion_group!(benches, decode_vs_ground_truth);
criterion_main!(benches);
