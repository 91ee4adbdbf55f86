//! The guard's cost beside what it guards (docs/GUARD.md; issue 73 target 4: the guard at
//! most 10 % of a surrogate's step), on the full-size `sheet-ms` after three frames: the
//! inertial predictor's proposal, the guard's estimate at it (residual and certificate), and
//! one ground-truth implicit-Euler step from the same state.

use criterion::{Criterion, criterion_group, criterion_main};
use weft_sim::guard::{Guard, GuardSettings, InertialPredictor, StepInput, Surrogate};
use weft_sim::{ClothScene, ClothSimulation};

fn guard(c: &mut Criterion) {
    let mut group = c.benchmark_group("guard");
    group.sample_size(10);
    let scene = ClothScene::builtin("sheet-ms", false).unwrap();
    let mut sim = ClothSimulation::new(scene.clone(), None).unwrap();
    for _ in 0..3 {
        sim.step().unwrap();
    }
    let prescribed = sim.prescribed_at(4);
    let mut predictor = InertialPredictor::for_integrator(sim.integrator());
    let mut guard = Guard::new(
        sim.integrator(),
        &scene.name,
        Box::new(predictor.clone()),
        GuardSettings::ground_truth(),
    )
    .unwrap();
    let integrator = sim.integrator();
    let input = StepInput {
        frame: 4,
        dt: integrator.dt(),
        current: integrator.positions(),
        previous: integrator.previous_positions(),
        prescribed: &prescribed,
    };
    let proposal = predictor.propose(&input).unwrap();
    group.bench_function("sheet-ms/inertial proposal", |b| {
        b.iter(|| predictor.propose(&input).unwrap())
    });
    group.bench_function("sheet-ms/guard estimate", |b| {
        b.iter(|| guard.estimate(integrator, &proposal).unwrap())
    });
    let (current, previous) = (
        integrator.positions().to_vec(),
        integrator.previous_positions().to_vec(),
    );
    group.bench_function("sheet-ms/ground-truth step", |b| {
        b.iter(|| {
            let integrator = sim.integrator_mut();
            integrator.set_state(&current, &previous).unwrap();
            integrator.step(&prescribed).unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, guard);
criterion_main!(benches);
