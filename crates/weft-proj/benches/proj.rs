//! Projection layers on the paper's size: `sheet(55, 1.0)` (3025 vertices, 8856 edges;
//! Geng et al.: 2969 vertices, 8787 constraints) under a smooth stretch-plus-noise
//! prediction. Measures SOCP forward / backward and quasistatic forward / backward.
//!
//! The quasistatic forward is measured with the Cholesky Newton (the default) and the
//! Newton–Krylov solve, each cold (Newton from the prediction) and warm (from the
//! equilibrium of a nearby prediction — the same example one training step earlier —
//! moved by the change of prediction).
//!
//! The SOCP forward is also measured warm: from the solution and active set of the same
//! example one training step earlier.
//!
//! The SOCP forward is measured with the default settings (reduced IPM, polish tried
//! from a relative gap of 1e-3) and, as same-run references, with the polish only
//! after the IPM has converged and with Clarabel as the conic solver.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::time::Instant;
use weft_proj::{
    ConicSolver, InextensibilityLayer, QuasistaticAdjoint, QuasistaticLayer, QuasistaticParams, QuasistaticSolver,
    SocpSettings, ZeroLengthScaling,
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

    // One training step earlier: a smooth change of about 2 mm and 0.5 mm of noise.
    let mut state: u64 = 0xC0FFEE;
    let earlier: Vec<f64> = pred
        .iter()
        .enumerate()
        .map(|(i, x)| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.001;
            x + 0.002 * (0.01 * i as f64).sin() + noise
        })
        .collect();
    let earlier_small: Vec<f64> = pred.iter().zip(&earlier).map(|(p, e)| p + 0.1 * (e - p)).collect();
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
    // A warm start: the solution of the same example one training step earlier, and one
    // from a change ten times smaller (late in training, when the network moves little).
    let (socp_earlier, _) = socp.forward(&earlier).expect("socp forward");
    let (socp_earlier_small, _) = socp.forward(&earlier_small).expect("socp forward");
    for (name, prev) in [("warm", &socp_earlier), ("warm small", &socp_earlier_small)] {
        let (_, r) = socp.forward_from(&pred, Some(prev)).expect("socp forward");
        eprintln!(
            "socp {name}: {} IPM iterations (0: the polish certified the warm start), {:?} polish steps",
            r.iterations, r.polish_iterations
        );
    }
    let mut group = c.benchmark_group("socp");
    group.sample_size(10);
    group.bench_function("forward", |b| {
        b.iter(|| socp.forward(black_box(&pred)).expect("forward"))
    });
    group.bench_function("forward_warm", |b| {
        b.iter(|| {
            socp.forward_from(black_box(&pred), Some(&socp_earlier))
                .expect("forward")
        })
    });
    group.bench_function("forward_warm_small", |b| {
        b.iter(|| {
            socp.forward_from(black_box(&pred), Some(&socp_earlier_small))
                .expect("forward")
        })
    });
    group.bench_function("backward", |b| {
        b.iter(|| socp.backward(&solution, black_box(&grad)).expect("backward"))
    });
    for (name, layer) in &references {
        group.bench_function(*name, |b| b.iter(|| layer.forward(black_box(&pred)).expect("forward")));
    }
    group.finish();

    let quasi = QuasistaticLayer::new(&rest, QuasistaticParams::default()).expect("quasistatic layer");
    let krylov = QuasistaticLayer::new(
        &rest,
        QuasistaticParams {
            solver: QuasistaticSolver::NewtonKrylov,
            ..QuasistaticParams::default()
        },
    )
    .expect("quasistatic layer");
    // The previous code path: the forward pass factorises H(r*) for the backward pass.
    let eager = QuasistaticLayer::new(
        &rest,
        QuasistaticParams {
            adjoint: QuasistaticAdjoint::FactorizeAtSolution,
            ..QuasistaticParams::default()
        },
    )
    .expect("quasistatic layer");
    let mu = ZeroLengthScaling::Global(0.1);
    let (qsol, qreport) = quasi.forward(&pred, &mu).expect("quasistatic forward");
    eprintln!("quasistatic: {qreport:?}");
    // Two warm starts: the earlier equilibrium as it is, and moved by the change of
    // prediction.
    let (prev, _) = quasi.forward(&earlier, &mu).expect("forward");
    let start = prev.positions().to_vec();
    let (prev_small, _) = quasi.forward(&earlier_small, &mu).expect("forward");
    let start_small = prev_small.positions().to_vec();
    let shifted: Vec<f64> = start
        .iter()
        .zip(pred.iter().zip(&earlier))
        .map(|(x, (p, q))| x + p - q)
        .collect();
    for (name, layer, s) in [
        ("cholesky warm", &quasi, Some(&start)),
        ("cholesky warm shifted", &quasi, Some(&shifted)),
        ("newton-krylov cold", &krylov, None),
        ("newton-krylov warm", &krylov, Some(&start)),
        ("cholesky warm small", &quasi, Some(&start_small)),
        ("newton-krylov warm small", &krylov, Some(&start_small)),
        ("newton-krylov warm shifted", &krylov, Some(&shifted)),
    ] {
        let (_, r) = layer
            .forward_from(&pred, &mu, s.map(|v| v.as_slice()))
            .expect("forward");
        eprintln!(
            "quasistatic {name}: {} Newton steps, {} factorisations, {} CG iterations, residual {:.1e} N",
            r.newton.iterations, r.newton.factorizations, r.cg_iterations, r.newton.residual
        );
    }
    let mut group = c.benchmark_group("quasistatic");
    group.sample_size(20);
    group.bench_function("forward", |b| {
        b.iter(|| quasi.forward(black_box(&pred), &mu).expect("forward"))
    });
    group.bench_function("forward_warm", |b| {
        b.iter(|| {
            quasi
                .forward_from(black_box(&pred), &mu, Some(&start))
                .expect("forward")
        })
    });
    group.bench_function("forward_newton_krylov", |b| {
        b.iter(|| krylov.forward(black_box(&pred), &mu).expect("forward"))
    });
    group.bench_function("forward_newton_krylov_warm", |b| {
        b.iter(|| {
            krylov
                .forward_from(black_box(&pred), &mu, Some(&start))
                .expect("forward")
        })
    });
    group.bench_function("forward_warm_small", |b| {
        b.iter(|| {
            quasi
                .forward_from(black_box(&pred), &mu, Some(&start_small))
                .expect("forward")
        })
    });
    group.bench_function("forward_newton_krylov_warm_small", |b| {
        b.iter(|| {
            krylov
                .forward_from(black_box(&pred), &mu, Some(&start_small))
                .expect("forward")
        })
    });
    group.bench_function("forward_newton_krylov_warm_shifted", |b| {
        b.iter(|| {
            krylov
                .forward_from(black_box(&pred), &mu, Some(&shifted))
                .expect("forward")
        })
    });
    group.bench_function("backward", |b| {
        b.iter(|| quasi.backward(&qsol, black_box(&grad)).expect("backward"))
    });
    // Same run, the previous path (H(r*) factorised in the forward pass), and a training
    // example's forward + backward both ways.
    group.bench_function("forward_factorize_at_solution", |b| {
        b.iter(|| eager.forward(black_box(&pred), &mu).expect("forward"))
    });
    let (esol, _) = eager.forward(&pred, &mu).expect("forward");
    group.bench_function("backward_factorize_at_solution", |b| {
        b.iter(|| eager.backward(&esol, black_box(&grad)).expect("backward"))
    });
    for (name, layer) in [
        ("forward_backward_warm_small", &quasi),
        ("forward_backward_warm_small_factorize_at_solution", &eager),
    ] {
        group.bench_function(name, |b| {
            b.iter(|| {
                let (sol, _) = layer
                    .forward_from(black_box(&pred), &mu, Some(&start_small))
                    .expect("forward");
                layer.backward(&sol, black_box(&grad)).expect("backward")
            })
        });
    }
    // The Newton–Krylov forward pass leaves no factor: its backward pass factorises.
    let (ksol, _) = krylov.forward(&pred, &mu).expect("forward");
    group.bench_function("backward_newton_krylov", |b| {
        b.iter(|| krylov.backward(&ksol, black_box(&grad)).expect("backward"))
    });
    group.finish();

    // The Hessian product CG spends its time on, on the quasistatic layer's pattern (edges,
    // bending pairs, axial quads): block by block against entry by entry over the same
    // stored entries (a copy of the pattern without its vertex-block index).
    let n = rest.num_vertices();
    let topology = quasi.rest().topology();
    let mut pairs: Vec<(usize, usize)> = topology.edges.iter().map(|&[a, b]| (a, b)).collect();
    for h in &topology.hinges {
        let q = [h.edge_vertices[0], h.edge_vertices[1], h.opposite[0], h.opposite[1]];
        for i in 0..4 {
            for j in i + 1..4 {
                pairs.push((q[i], q[j]));
            }
        }
    }
    let blocks = std::sync::Arc::new(weft_linalg::SymmetricPattern::from_vertex_pairs(n, pairs));
    let entries = std::sync::Arc::new(weft_linalg::SymmetricPattern::new(
        3 * n,
        blocks.entries().map(|(_, r, c)| (r, c)),
    ));
    let mut by_block = weft_linalg::SymmetricMatrix::zeros(blocks.clone());
    by_block
        .values_mut()
        .iter_mut()
        .enumerate()
        .for_each(|(i, v)| *v = (0.7 * i as f64).sin());
    let mut by_entry = weft_linalg::SymmetricMatrix::zeros(entries);
    by_entry.add_matrix(&by_block).expect("the same entries");
    eprintln!("quasistatic Hessian: {} stored entries", blocks.nnz());
    let x: Vec<f64> = (0..3 * n).map(|i| (0.3 * i as f64).cos()).collect();
    let mut y = vec![0.0; 3 * n];
    let mut group = c.benchmark_group("quasistatic");
    group.bench_function("hessian_product_blocks", |b| {
        b.iter(|| by_block.mul_vec(black_box(&x), &mut y))
    });
    group.bench_function("hessian_product_entries", |b| {
        b.iter(|| by_entry.mul_vec(black_box(&x), &mut y))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
