//! Projection layers on the paper's size: `sheet(55, 1.0)` (3025 vertices, 8856 edges;
//! Geng et al.: 2969 vertices, 8787 constraints) under a smooth stretch-plus-noise
//! prediction. Measures SOCP forward / backward and quasistatic forward / backward.
//!
//! The SOCP forward is measured with the default settings (reduced IPM, polish tried
//! from a relative gap of 1e-3) and, as same-run references, with the polish only
//! after the IPM has converged and with Clarabel as the conic solver.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Instant;
use weft_proj::{
    ConicSolver, InextensibilityLayer, QuasistaticLayer, QuasistaticParams, SocpSettings, ZeroLengthScaling,
};

/// A network-like prediction: 15 % stretch along x, 5 % along y, a smooth bump and
/// deterministic noise of about a tenth of an edge length.
fn prediction(rest: &weft_mesh::TriMesh) -> Vec<f64> {
    let mut state: u64 = 0x5EED;
    let mut noise = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.004
    };
    rest.positions()
        .iter()
        .flat_map(|p| {
            let z = 0.05 * (4.0 * p.x).sin() * (3.0 * p.y).cos();
            [1.15 * p.x + noise(), 1.05 * p.y + noise(), z + noise()]
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let rest = weft_mesh::generators::sheet(55, 1.0).expect("sheet");
    let pred = prediction(&rest);
    let grad: Vec<f64> = (0..pred.len()).map(|i| (0.37 * i as f64).sin()).collect();

    let start = Instant::now();
    let socp = InextensibilityLayer::new(&rest, 0.1, SocpSettings::default()).expect("socp layer");
    eprintln!("socp layer construction: {:.1} ms", 1e3 * start.elapsed().as_secs_f64());
    let (solution, report) = socp.forward(&pred).expect("socp forward");
    eprintln!("socp: {report:?}");
    let references = [
        (
            "forward_polish_after_convergence",
            SocpSettings {
                early_polish_gap: 0.0,
                ..SocpSettings::default()
            },
        ),
        (
            "forward_clarabel",
            SocpSettings {
                solver: ConicSolver::Clarabel,
                ..SocpSettings::default()
            },
        ),
    ]
    .map(|(name, settings)| {
        let layer = InextensibilityLayer::new(&rest, 0.1, settings).expect("socp layer");
        let (_, report) = layer.forward(&pred).expect("socp forward");
        eprintln!("socp {name}: {report:?}");
        (name, layer)
    });
    let mut group = c.benchmark_group("socp");
    group.sample_size(10);
    group.bench_function("forward", |b| {
        b.iter(|| socp.forward(black_box(&pred)).expect("forward"))
    });
    group.bench_function("backward", |b| {
        b.iter(|| socp.backward(&solution, black_box(&grad)).expect("backward"))
    });
    for (name, layer) in &references {
        group.bench_function(*name, |b| b.iter(|| layer.forward(black_box(&pred)).expect("forward")));
    }
    group.finish();

    let quasi = QuasistaticLayer::new(&rest, QuasistaticParams::default()).expect("quasistatic layer");
    let mu = ZeroLengthScaling::Global(0.1);
    let (qsol, qreport) = quasi.forward(&pred, &mu).expect("quasistatic forward");
    eprintln!("quasistatic: {qreport:?}");
    let mut group = c.benchmark_group("quasistatic");
    group.sample_size(20);
    group.bench_function("forward", |b| {
        b.iter(|| quasi.forward(black_box(&pred), &mu).expect("forward"))
    });
    group.bench_function("backward", |b| {
        b.iter(|| quasi.backward(&qsol, black_box(&grad)).expect("backward"))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
