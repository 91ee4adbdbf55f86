//! Integration tests of weft-proj: forward correctness against independent methods,
//! backward passes against central finite differences of the forward solve, bad input.

use nalgebra::Vector3;
use weft_mesh::{TriMesh, generators};
use weft_proj::{
    ConicSolver, Error, InextensibilityLayer, QuasistaticLayer, QuasistaticParams, SocpSettings, ZeroLengthScaling,
    strain_summary,
};
use weft_sim::Energy;
use weft_testkit::{TestRng, assert_close, fd_gradient, max_norm_rel_error};

/// `sheet(n)` with every interior vertex jittered in-plane: an irregular rest mesh.
fn random_sheet(n: usize, rng: &mut TestRng) -> TriMesh {
    let sheet = generators::sheet(n, 1.0).unwrap();
    let h = 1.0 / (n - 1) as f64;
    let p = sheet
        .positions()
        .iter()
        .map(|p| {
            let interior = p.x.abs() < 0.5 - 1e-9 && p.y.abs() < 0.5 - 1e-9;
            let j = if interior { 0.2 * h } else { 0.0 };
            Vector3::new(p.x + rng.uniform(-j, j), p.y + rng.uniform(-j, j), 0.0)
        })
        .collect();
    sheet.with_positions(p).unwrap()
}

/// A network-like prediction: stretch `sx` along x, a smooth bump, and noise.
fn predict(rest: &TriMesh, sx: f64, noise: f64, rng: &mut TestRng) -> Vec<f64> {
    rest.positions()
        .iter()
        .flat_map(|p| {
            let z = 0.1 * (3.0 * p.x).sin() * (2.0 * p.y).cos();
            [
                sx * p.x + rng.uniform(-noise, noise),
                p.y + rng.uniform(-noise, noise),
                z + rng.uniform(-noise, noise),
            ]
        })
        .collect()
}

/// Every edge's length over its rest length at the flat positions `x`.
fn edge_ratios(layer: &InextensibilityLayer, x: &[f64]) -> Vec<f64> {
    let rest = layer.rest();
    rest.edges()
        .iter()
        .zip(rest.rest_lengths())
        .map(|(&[a, b], l0)| {
            let d = Vector3::new(
                x[3 * a] - x[3 * b],
                x[3 * a + 1] - x[3 * b + 1],
                x[3 * a + 2] - x[3 * b + 2],
            );
            d.norm() / l0
        })
        .collect()
}

/// A prediction stretched 60 % in-plane: with ε = 0.05, most constraints are active.
fn stretch_in_plane(rest: &TriMesh, rng: &mut TestRng) -> Vec<f64> {
    predict(rest, 1.0, 0.02, rng)
        .iter()
        .enumerate()
        .map(|(i, x)| if i % 3 == 2 { *x } else { 1.6 * x })
        .collect()
}

fn max_edge_ratio(layer: &InextensibilityLayer, x: &[f64]) -> f64 {
    edge_ratios(layer, x).into_iter().fold(0.0, f64::max)
}

/// Dykstra's alternating projections in the `K`-weighted norm: converges to the
/// `K`-weighted projection of `pred` onto the intersection of the convex edge sets
/// `‖r_a − r_b‖ ≤ l^max` — an independent solver for Geng et al. Eq. 1.
fn dykstra(layer: &InextensibilityLayer, pred: &[f64], sweeps: usize) -> Vec<f64> {
    let rest = layer.rest();
    let k = rest.weights();
    let eps = layer.epsilon();
    let mut x = pred.to_vec();
    let mut incr = vec![[0.0; 6]; rest.edges().len()];
    for _ in 0..sweeps {
        for (e, (&[a, b], &l0)) in rest.edges().iter().zip(rest.rest_lengths()).enumerate() {
            let lmax = (1.0 + eps) * l0;
            let mut y = [0.0; 6];
            for c in 0..3 {
                y[c] = x[3 * a + c] + incr[e][c];
                y[3 + c] = x[3 * b + c] + incr[e][3 + c];
            }
            let d = Vector3::new(y[0] - y[3], y[1] - y[4], y[2] - y[5]);
            let l = d.norm();
            let mut p = y;
            if l > lmax {
                // Weighted projection: the mass-weighted centre stays, the length becomes lmax.
                let (ka, kb) = (k[a], k[b]);
                let u = d / l;
                for c in 0..3 {
                    let centre = (ka * y[c] + kb * y[3 + c]) / (ka + kb);
                    p[c] = centre + kb / (ka + kb) * lmax * u[c];
                    p[3 + c] = centre - ka / (ka + kb) * lmax * u[c];
                }
            }
            for c in 0..6 {
                incr[e][c] = y[c] - p[c];
            }
            for c in 0..3 {
                x[3 * a + c] = p[c];
                x[3 * b + c] = p[3 + c];
            }
        }
    }
    x
}

#[test]
fn socp_forward_meets_bounds_and_kkt_on_a_stretched_sheet() {
    let mut rng = TestRng::new(1);
    let rest = random_sheet(12, &mut rng);
    let pred = predict(&rest, 1.25, 0.01, &mut rng);
    let layer = InextensibilityLayer::new(&rest, 0.1, SocpSettings::default()).unwrap();
    assert!(
        max_edge_ratio(&layer, &pred) > 1.2,
        "the prediction must violate the bounds"
    );
    let (sol, report) = layer.forward(&pred).unwrap();
    assert!(max_edge_ratio(&layer, sol.positions()) <= 1.1 * (1.0 + 1e-6));
    assert!(report.max_violation <= 1e-6, "{report:?}");
    assert!(report.kkt_residual < 1e-6, "{report:?}");
    assert!(report.active_constraints > 0 && report.active_constraints < report.num_constraints);
    assert_eq!(report.status, "Solved");
}

#[test]
fn socp_forward_matches_dykstra_projection() {
    let mut rng = TestRng::new(2);
    let rest = random_sheet(5, &mut rng);
    let pred = predict(&rest, 1.3, 0.03, &mut rng);
    let layer = InextensibilityLayer::new(&rest, 0.05, SocpSettings::tight()).unwrap();
    let (sol, _) = layer.forward(&pred).unwrap();
    let reference = dykstra(&layer, &pred, 20_000);
    let err = max_norm_rel_error(sol.positions(), &reference);
    assert!(err < 1e-7, "SOCP vs Dykstra: relative error {err:e}");
}

#[test]
fn socp_leaves_a_feasible_prediction_alone_and_backward_is_identity() {
    let rest = generators::sheet(6, 1.0).unwrap();
    let pred: Vec<f64> = rest.flat_positions().iter().map(|x| 0.9 * x).collect();
    let layer = InextensibilityLayer::new(&rest, 0.0, SocpSettings::tight()).unwrap();
    let (sol, report) = layer.forward(&pred).unwrap();
    assert_eq!(report.active_constraints, 0);
    assert!(max_norm_rel_error(sol.positions(), &pred) < 1e-9);
    let g: Vec<f64> = (0..pred.len()).map(|i| (i as f64 * 0.37).sin()).collect();
    let gi = layer.backward(&sol, &g).unwrap();
    assert!(max_norm_rel_error(&gi, &g) < 1e-8);
}

/// Checks `∂(gᵀ r*)/∂r̂` from the backward pass against central differences of forward.
fn check_socp_backward(layer: &InextensibilityLayer, pred: &[f64], seed: u64) -> (usize, usize) {
    let mut rng = TestRng::new(seed);
    let g = rng.vec(pred.len(), -1.0, 1.0);
    let (sol, report) = layer.forward(pred).unwrap();
    let (analytic, back) = layer.backward_with_report(&sol, &g).unwrap();
    assert!(back.linear_residual < 1e-8, "{back:?}");
    let loss = |x: &[f64]| {
        let (s, _) = layer.forward(x).unwrap();
        s.positions().iter().zip(&g).map(|(a, b)| a * b).sum::<f64>()
    };
    let fd = fd_gradient(loss, pred, 1e-5);
    let err = max_norm_rel_error(&analytic, &fd);
    assert!(err < 1e-4, "SOCP backward vs FD: relative error {err:e} ({report:?})");
    (report.active_constraints, report.num_constraints)
}

#[test]
fn socp_backward_matches_finite_differences_on_random_meshes() {
    for seed in 0..3 {
        let mut rng = TestRng::new(10 + seed);
        let rest = random_sheet(5, &mut rng);
        let pred = predict(&rest, 1.15, 0.05, &mut rng);
        let layer = InextensibilityLayer::new(&rest, 0.1, SocpSettings::tight()).unwrap();
        let (active, total) = check_socp_backward(&layer, &pred, seed);
        assert!(
            active > 0 && active < total,
            "mixed active set expected: {active}/{total}"
        );
    }
}

#[test]
fn socp_backward_matches_finite_differences_with_most_constraints_active() {
    let mut rng = TestRng::new(20);
    let rest = random_sheet(5, &mut rng);
    let pred = stretch_in_plane(&rest, &mut rng);
    let layer = InextensibilityLayer::new(&rest, 0.05, SocpSettings::tight()).unwrap();
    let (active, total) = check_socp_backward(&layer, &pred, 21);
    assert!(
        active * 10 >= total * 8,
        "most constraints should be active: {active}/{total}"
    );
}

/// Geng et al. Fig. 11 / Appendix A: three collinear, maximally stretched edges whose
/// multipliers are not unique (a null space of Eq. 7). The rest mesh has a zero-area
/// face (0, 2, 1) so that l̄_02 = l̄_01 + l̄_12, and the prediction is collinear too.
/// Along the line the derivative is independent of the multiplier split and the
/// regularised LDLᵀ must reproduce it; perpendicular to the line it is not (see
/// docs/PROJECTION.md), so the finite-difference check covers the in-line coordinates
/// of the degenerate triangle and every coordinate of the other two vertices.
#[test]
fn socp_backward_is_robust_in_the_collinear_degenerate_case() {
    let (rest, pred) = collinear_case();
    let layer = InextensibilityLayer::new(&rest, 0.1, SocpSettings::tight()).unwrap();
    let (sol, report) = layer.forward(&pred).unwrap();
    let x = sol.positions();
    let len = |a: usize, b: usize| {
        Vector3::new(
            x[3 * a] - x[3 * b],
            x[3 * a + 1] - x[3 * b + 1],
            x[3 * a + 2] - x[3 * b + 2],
        )
        .norm()
    };
    // All three edges of the degenerate triangle sit at their bounds.
    assert_close!(len(0, 1), 1.1, rtol = 1e-9, atol = 0.0);
    assert_close!(len(1, 2), 1.1, rtol = 1e-9, atol = 0.0);
    assert_close!(len(0, 2), 2.2, rtol = 1e-9, atol = 0.0);
    assert!(report.active_constraints >= 3, "{report:?}");
    assert!(report.kkt_residual < 1e-9, "{report:?}");

    let mut rng = TestRng::new(30);
    let g = rng.vec(pred.len(), -1.0, 1.0);
    let (analytic, back) = layer.backward_with_report(&sol, &g).unwrap();
    assert!(analytic.iter().all(|v| v.is_finite()));
    assert!(back.linear_residual < 1e-8, "{back:?}");
    let loss = |y: &[f64]| {
        let (s, _) = layer.forward(y).unwrap();
        s.positions().iter().zip(&g).map(|(a, b)| a * b).sum::<f64>()
    };
    let dofs = [0, 3, 6, 9, 10, 11, 12, 13, 14];
    let mut fd = Vec::new();
    let mut an = Vec::new();
    for &i in &dofs {
        let mut e = vec![0.0; pred.len()];
        e[i] = 1.0;
        fd.push(weft_testkit::fd_directional(|y: &[f64]| vec![loss(y)], &pred, &e, 1e-5)[0]);
        an.push(analytic[i]);
    }
    let err = max_norm_rel_error(&an, &fd);
    assert!(
        err < 1e-4,
        "degenerate SOCP backward vs FD: relative error {err:e}: {an:?} vs {fd:?}"
    );
}

/// Edges within a relative `1e-6` of their bound at the flat positions `x`.
fn active_edges(layer: &InextensibilityLayer, x: &[f64]) -> Vec<bool> {
    let bound = 1.0 + layer.epsilon();
    edge_ratios(layer, x)
        .into_iter()
        .map(|r| r / bound > 1.0 - 1e-6)
        .collect()
}

/// The rest mesh and prediction of Geng et al. Fig. 11: a zero-area rest triangle
/// (0, 2, 1) whose three edges are all stretched along one line.
fn collinear_case() -> (TriMesh, Vec<f64>) {
    let p = vec![
        Vector3::new(-1.0, 0.0, 0.0),
        Vector3::new(0.0, 0.0, 0.0),
        Vector3::new(1.0, 0.0, 0.0),
        Vector3::new(0.0, 1.0, 0.0),
        Vector3::new(0.0, -1.0, 0.0),
    ];
    let rest = TriMesh::new(p, vec![[0, 1, 3], [1, 2, 3], [0, 2, 1], [0, 4, 2]]).unwrap();
    let pred = vec![
        -1.5, 0.0, 0.0, 0.1, 0.0, 0.0, 1.5, 0.0, 0.0, 0.0, 0.3, 0.0, 0.0, -0.3, 0.0,
    ];
    (rest, pred)
}

/// Stretched sheets with mixed active sets, one with most constraints active, and the
/// degenerate collinear case: (rest mesh, prediction, ε).
fn cross_check_cases() -> Vec<(TriMesh, Vec<f64>, f64)> {
    let mut cases = Vec::new();
    for seed in 0..3 {
        let mut rng = TestRng::new(100 + seed);
        let rest = random_sheet(6, &mut rng);
        let pred = predict(&rest, 1.15 + 0.05 * seed as f64, 0.04, &mut rng);
        cases.push((rest, pred, 0.1));
    }
    let mut rng = TestRng::new(110);
    let rest = random_sheet(6, &mut rng);
    let pred = stretch_in_plane(&rest, &mut rng);
    cases.push((rest, pred, 0.05));
    let (rest, pred) = collinear_case();
    cases.push((rest, pred, 0.1));
    cases
}

#[test]
fn reduced_ipm_agrees_with_clarabel() {
    let with = |solver, polish| SocpSettings {
        solver,
        polish,
        ..SocpSettings::tight()
    };
    let mut mostly_active = false;
    for (rest, pred, eps) in cross_check_cases() {
        for polish in [true, false] {
            let ipm = InextensibilityLayer::new(&rest, eps, with(ConicSolver::ReducedIpm, polish)).unwrap();
            let clarabel = InextensibilityLayer::new(&rest, eps, with(ConicSolver::Clarabel, polish)).unwrap();
            let (a, report_a) = ipm.forward(&pred).unwrap();
            let (b, report_b) = clarabel.forward(&pred).unwrap();
            let err = max_norm_rel_error(a.positions(), b.positions());
            // Polished, both are the exact projection. Unpolished, each stops at a relative
            // gap of 1e-10; on weakly active edges (s_e, z_e both ~√μ) positions then
            // carry errors ~√gap, measured at up to 1.8e-7 for either solver.
            let allowed = if polish { 1e-10 } else { 1e-6 };
            assert!(
                err < allowed,
                "polish {polish}: IPM vs Clarabel {err:e}\n{report_a:?}\n{report_b:?}"
            );
            assert_eq!(report_a.polish_iterations.is_some(), polish, "{report_a:?}");
            if polish {
                assert_eq!(
                    active_edges(&ipm, a.positions()),
                    active_edges(&clarabel, b.positions())
                );
                assert_eq!(report_a.active_constraints, report_b.active_constraints);
            }
            mostly_active |= report_a.active_constraints * 10 >= report_a.num_constraints * 8;
        }
    }
    assert!(mostly_active, "one case must have most constraints active");
}

#[test]
fn reduced_ipm_alone_meets_bounds_and_kkt_to_its_tolerance() {
    for (rest, pred, eps) in cross_check_cases() {
        for tolerance in [1e-6, 1e-9] {
            let settings = SocpSettings {
                solver: ConicSolver::ReducedIpm,
                polish: false,
                tolerance,
                ..SocpSettings::default()
            };
            let layer = InextensibilityLayer::new(&rest, eps, settings).unwrap();
            let (sol, report) = layer.forward(&pred).unwrap();
            assert_eq!(report.status, "Solved");
            assert!(report.polish_iterations.is_none());
            assert!(report.iterations > 0 && report.iterations < 50, "{report:?}");
            assert!(
                report.primal_residual <= tolerance && report.dual_residual <= tolerance,
                "{report:?}"
            );
            // Every bound holds to the primal tolerance, and the KKT conditions hold to
            // within a small multiple of it (complementarity is relative per edge).
            assert!(report.max_violation <= tolerance, "{report:?}");
            assert!(max_edge_ratio(&layer, sol.positions()) <= (1.0 + eps) * (1.0 + tolerance));
            assert!(report.kkt_residual <= 100.0 * tolerance, "{report:?}");
        }
    }
}

/// Forward and backward (output gradient `g`) on a fresh layer: positions, forward
/// report, input gradient; the backward's linear residual is checked.
fn forward_backward(
    rest: &TriMesh,
    eps: f64,
    settings: SocpSettings,
    pred: &[f64],
    g: &[f64],
) -> (Vec<f64>, weft_proj::SocpReport, Vec<f64>) {
    let layer = InextensibilityLayer::new(rest, eps, settings).unwrap();
    let (sol, report) = layer.forward(pred).unwrap();
    let (grad, back) = layer.backward_with_report(&sol, g).unwrap();
    assert!(back.linear_residual < 1e-8, "{back:?}");
    (sol.into_positions(), report, grad)
}

/// Without the polish every edge carries some force and the backward pass factorises
/// the full edge system; with it, the active edges' system that the polish built. On
/// the mixed-active-set sheets both give the same gradient up to the interior-point
/// tolerance (measured ≤ 1.1e-6; weakly active edges of an interior point still carry
/// part of their force, so the unpolished derivative is only close to the exact one).
#[test]
fn socp_backward_agrees_with_and_without_polish() {
    for (rest, pred, eps) in cross_check_cases().into_iter().take(3) {
        let g: Vec<f64> = (0..pred.len()).map(|i| (0.37 * i as f64).sin()).collect();
        let gradient = |polish| {
            let settings = SocpSettings {
                polish,
                ..SocpSettings::tight()
            };
            forward_backward(&rest, eps, settings, &pred, &g).2
        };
        let err = max_norm_rel_error(&gradient(false), &gradient(true));
        assert!(err < 1e-5, "unpolished vs polished backward: {err:e}");
    }
}

/// The polish tried early (the default: from the first iterate with a relative gap
/// below `early_polish_gap`) or only after the interior-point method converged must
/// certify the same projection and give the same gradient: an accepted polish is the
/// unique optimum to round-off.
#[test]
fn early_polish_gives_the_same_projection_and_gradient() {
    let mut handed_over_early = false;
    for (rest, pred, eps) in cross_check_cases() {
        let g: Vec<f64> = (0..pred.len()).map(|i| (0.37 * i as f64).cos()).collect();
        let run = |early_polish_gap| {
            let settings = SocpSettings {
                early_polish_gap,
                ..SocpSettings::default()
            };
            let (positions, report, grad) = forward_backward(&rest, eps, settings, &pred, &g);
            assert!(
                report.polish_iterations.is_some() && report.kkt_residual < 1e-12,
                "{report:?}"
            );
            (positions, grad, report.iterations)
        };
        let (late, early) = (run(0.0), run(SocpSettings::default().early_polish_gap));
        assert!(early.2 <= late.2);
        handed_over_early |= early.2 < late.2;
        assert!(max_norm_rel_error(&early.0, &late.0) < 1e-12);
        assert!(max_norm_rel_error(&early.1, &late.1) < 1e-8);
    }
    assert!(handed_over_early, "no case accepted the early polish");
}

#[test]
fn reduced_ipm_reports_non_convergence_as_a_typed_error() {
    let mut rng = TestRng::new(120);
    let rest = random_sheet(5, &mut rng);
    let pred = predict(&rest, 1.3, 0.02, &mut rng);
    let settings = SocpSettings {
        max_iterations: 2,
        ..SocpSettings::default()
    };
    let layer = InextensibilityLayer::new(&rest, 0.1, settings).unwrap();
    match layer.forward(&pred) {
        Err(Error::SolverFailed { status, iterations }) => {
            assert_eq!(status, "MaxIterations");
            assert_eq!(iterations, 2);
        }
        other => panic!("expected SolverFailed, got {other:?}"),
    }
}

#[test]
fn socp_batch_matches_serial() {
    let mut rng = TestRng::new(40);
    let rest = random_sheet(6, &mut rng);
    let layer = InextensibilityLayer::new(&rest, 0.1, SocpSettings::default()).unwrap();
    let preds: Vec<Vec<f64>> = (0..4).map(|_| predict(&rest, 1.2, 0.02, &mut rng)).collect();
    let grads: Vec<Vec<f64>> = (0..4).map(|_| rng.vec(preds[0].len(), -1.0, 1.0)).collect();
    let batch: Vec<_> = layer.forward_batch(&preds).into_iter().map(|r| r.unwrap().0).collect();
    let batch_grads = layer.backward_batch(&batch, &grads).unwrap();
    for i in 0..4 {
        let (serial, _) = layer.forward(&preds[i]).unwrap();
        assert_eq!(serial.positions(), batch[i].positions());
        assert_eq!(layer.backward(&serial, &grads[i]).unwrap(), batch_grads[i]);
    }
}

#[test]
fn socp_rejects_bad_input() {
    let rest = generators::sheet(4, 1.0).unwrap();
    assert!(matches!(
        InextensibilityLayer::new(&rest, -0.1, SocpSettings::default()),
        Err(Error::InvalidParameter { name: "epsilon", .. })
    ));
    assert!(matches!(
        InextensibilityLayer::new(&rest, f64::NAN, SocpSettings::default()),
        Err(Error::InvalidParameter { .. })
    ));
    let negative_gap = SocpSettings {
        early_polish_gap: -1.0,
        ..SocpSettings::default()
    };
    assert!(matches!(
        InextensibilityLayer::new(&rest, 0.1, negative_gap),
        Err(Error::InvalidParameter {
            name: "early_polish_gap",
            ..
        })
    ));
    let layer = InextensibilityLayer::new(&rest, 0.1, SocpSettings::default()).unwrap();
    let mut pred = rest.flat_positions();
    pred[7] = f64::NAN;
    assert!(matches!(layer.forward(&pred), Err(Error::NonFinite { index: 7, .. })));
    assert!(matches!(layer.forward(&pred[..9]), Err(Error::LengthMismatch { .. })));
    let good = rest.flat_positions();
    let (sol, _) = layer.forward(&good).unwrap();
    let mut g = vec![1.0; good.len()];
    g[0] = f64::INFINITY;
    assert!(matches!(layer.backward(&sol, &g), Err(Error::NonFinite { .. })));
    assert!(matches!(
        layer.backward(&sol, &g[..3]),
        Err(Error::LengthMismatch { .. })
    ));

    // Two coincident rest vertices joined by an edge.
    let mut p = rest.positions().to_vec();
    p[1] = p[0];
    let degenerate = rest.with_positions(p).unwrap();
    assert!(matches!(
        InextensibilityLayer::new(&degenerate, 0.1, SocpSettings::default()),
        Err(Error::DegenerateRestEdge { .. })
    ));
    assert!(matches!(
        QuasistaticLayer::new(&degenerate, QuasistaticParams::default()),
        Err(Error::DegenerateRestEdge { .. })
    ));
}

fn tight_quasistatic() -> QuasistaticParams {
    QuasistaticParams {
        tolerance: 1e-11,
        ..QuasistaticParams::default()
    }
}

#[test]
fn quasistatic_recovers_from_stretched_and_inverted_predictions() {
    let mut rng = TestRng::new(50);
    let rest = random_sheet(10, &mut rng);
    let layer = QuasistaticLayer::new(&rest, QuasistaticParams::default()).unwrap();
    let (ne, nb, na) = layer.spring_counts();
    assert_eq!(ne, layer.rest().edges().len());
    assert_eq!(nb, layer.rest().topology().hinges.len());
    assert_eq!(na, nb);
    // Mirrored in x (every triangle inverted) and stretched 3×, with noise.
    let inverted: Vec<f64> = predict(&rest, -3.0, 0.02, &mut rng)
        .iter()
        .enumerate()
        .map(|(i, x)| if i % 3 == 1 { 1.5 * x } else { *x })
        .collect();
    let before = strain_summary(layer.rest(), &inverted, 1.0).unwrap();
    for mu in [1.0, 0.1, 0.01] {
        let (sol, report) = layer.forward(&inverted, &ZeroLengthScaling::Global(mu)).unwrap();
        // (Finiteness is part of `Ok`; what matters is that the equilibrium was reached.)
        assert!(report.newton.residual < 1e-6 * report.newton.initial_residual);
        let after = strain_summary(layer.rest(), sol.positions(), 1.0).unwrap();
        // Stiff anchors (μ = 1) keep r* near the bad prediction; weak ones relax it.
        let factor = if mu < 0.05 { 0.1 } else { 0.6 };
        assert!(
            after.stretching_energy < factor * before.stretching_energy,
            "mu = {mu}: {before:?} → {after:?}"
        );
    }
    // Weaker anchors let the cloth relax further toward its rest lengths.
    let strain_at = |mu: f64| {
        let (sol, _) = layer.forward(&inverted, &ZeroLengthScaling::Global(mu)).unwrap();
        strain_summary(layer.rest(), sol.positions(), 1.0).unwrap().max_strain
    };
    assert!(strain_at(0.01) < strain_at(1.0));
}

#[test]
fn quasistatic_equilibrium_has_zero_net_force() {
    let mut rng = TestRng::new(55);
    let rest = random_sheet(6, &mut rng);
    let params = tight_quasistatic();
    let layer = QuasistaticLayer::new(&rest, params).unwrap();
    let pred = predict(&rest, 1.3, 0.05, &mut rng);
    let (sol, _) = layer.forward(&pred, &ZeroLengthScaling::Global(0.1)).unwrap();
    // Rebuild the energy independently from weft-sim's terms and check ∇E(r*) = 0.
    let x = sol.positions();
    let edges =
        weft_sim::energies::Springs::at_rest("e", rest.positions(), layer.rest().edges().to_vec(), 1.0).unwrap();
    let hinges = &layer.rest().topology().hinges;
    let bends =
        weft_sim::energies::Springs::at_rest("b", rest.positions(), hinges.iter().map(|h| h.opposite).collect(), 0.1)
            .unwrap();
    let axial = weft_proj::AxialSprings::new(layer.rest(), 0.1).unwrap();
    let w: Vec<f64> = layer.zero_length_base().iter().map(|k| 0.1 * k).collect();
    let anchors = weft_sim::energies::ZeroLengthSprings::new("z", w, pred.clone()).unwrap();
    let mut grad = vec![0.0; x.len()];
    for t in [&edges as &dyn Energy, &bends, &axial, &anchors] {
        t.add_gradient(x, &mut grad);
    }
    let max = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
    assert!(max < 1e-11, "residual force {max:e}");
}

#[test]
fn quasistatic_backward_matches_finite_differences() {
    for (seed, mu) in [(60, 1.0), (61, 0.1), (62, 0.01)] {
        let mut rng = TestRng::new(seed);
        let rest = random_sheet(5, &mut rng);
        let layer = QuasistaticLayer::new(&rest, tight_quasistatic()).unwrap();
        let pred = predict(&rest, 1.4, 0.05, &mut rng);
        let g = rng.vec(pred.len(), -1.0, 1.0);
        let scaling = ZeroLengthScaling::Global(mu);
        let (sol, _) = layer.forward(&pred, &scaling).unwrap();
        let grad = layer.backward(&sol, &g).unwrap();
        let loss_pred = |x: &[f64]| {
            let (s, _) = layer.forward(x, &scaling).unwrap();
            s.positions().iter().zip(&g).map(|(a, b)| a * b).sum::<f64>()
        };
        let fd = fd_gradient(loss_pred, &pred, 1e-6);
        let err = max_norm_rel_error(&grad.pred, &fd);
        assert!(err < 1e-4, "mu = {mu}: ∂E/∂r̂ vs FD relative error {err:e}");
        // ∂E/∂μ for a global μ (Eq. 16).
        let loss_mu = |m: &[f64]| {
            let (s, _) = layer.forward(&pred, &ZeroLengthScaling::Global(m[0])).unwrap();
            s.positions().iter().zip(&g).map(|(a, b)| a * b).sum::<f64>()
        };
        let fd_mu = fd_gradient(loss_mu, &[mu], 1e-6 * mu)[0];
        assert_close!(grad.mu, fd_mu, rtol = 1e-4, atol = 1e-10);
    }
}

#[test]
fn quasistatic_per_vertex_mu_gradient_matches_finite_differences() {
    let mut rng = TestRng::new(70);
    let rest = random_sheet(5, &mut rng);
    let layer = QuasistaticLayer::new(&rest, tight_quasistatic()).unwrap();
    let pred = predict(&rest, 1.3, 0.05, &mut rng);
    let mu = rng.vec(layer.num_vertices(), 0.02, 0.2);
    let g = rng.vec(pred.len(), -1.0, 1.0);
    let (sol, _) = layer.forward(&pred, &ZeroLengthScaling::PerVertex(mu.clone())).unwrap();
    let grad = layer.backward(&sol, &g).unwrap();
    let loss = |m: &[f64]| {
        let (s, _) = layer.forward(&pred, &ZeroLengthScaling::PerVertex(m.to_vec())).unwrap();
        s.positions().iter().zip(&g).map(|(a, b)| a * b).sum::<f64>()
    };
    let fd = fd_gradient(loss, &mu, 1e-7);
    let err = max_norm_rel_error(&grad.mu_per_vertex, &fd);
    assert!(err < 1e-4, "∂E/∂μ_i vs FD relative error {err:e}");
    assert_close!(grad.mu, fd.iter().sum::<f64>(), rtol = 1e-4, atol = 1e-10);
}

#[test]
fn quasistatic_batch_matches_serial() {
    let mut rng = TestRng::new(80);
    let rest = random_sheet(6, &mut rng);
    let layer = QuasistaticLayer::new(&rest, QuasistaticParams::default()).unwrap();
    let preds: Vec<Vec<f64>> = (0..4).map(|_| predict(&rest, 1.2, 0.02, &mut rng)).collect();
    let grads: Vec<Vec<f64>> = (0..4).map(|_| rng.vec(preds[0].len(), -1.0, 1.0)).collect();
    let scaling = ZeroLengthScaling::Global(0.1);
    let batch: Vec<_> = layer
        .forward_batch(&preds, &scaling)
        .into_iter()
        .map(|r| r.unwrap().0)
        .collect();
    let batch_grads = layer.backward_batch(&batch, &grads).unwrap();
    for i in 0..4 {
        let (serial, _) = layer.forward(&preds[i], &scaling).unwrap();
        assert_eq!(serial.positions(), batch[i].positions());
        assert_eq!(layer.backward(&serial, &grads[i]).unwrap(), batch_grads[i]);
    }
    // Warm starts per example: each entry is the serial solve from its own start (or
    // from its prediction), and a start list of another length is refused entry by entry.
    let starts: Vec<Option<Vec<f64>>> = vec![None, Some(batch[1].positions().to_vec()), None, Some(preds[0].clone())];
    let warm = layer.forward_batch_from(&preds, &scaling, &starts);
    for (i, r) in warm.into_iter().enumerate() {
        let (serial, _) = layer.forward_from(&preds[i], &scaling, starts[i].as_deref()).unwrap();
        assert_eq!(r.unwrap().0.positions(), serial.positions(), "example {i}");
    }
    let short = layer.forward_batch_from(&preds, &scaling, &starts[..3]);
    assert_eq!(short.len(), 4);
    assert!(short.iter().all(|r| matches!(
        r,
        Err(Error::LengthMismatch {
            expected: 4,
            got: 3,
            ..
        })
    )));
}

#[test]
fn warm_starts_return_what_was_remembered_for_each_key() {
    let store: weft_proj::WarmStarts<i64, Vec<f64>> = Default::default();
    assert_eq!(store.starts(None, 2), vec![None, None], "no keys: a cold batch");
    assert_eq!(store.starts(Some(&[3, 7]), 2), vec![None, None]);
    store.remember(Some(&[7, 3]), [vec![7.0], vec![3.0]].into_iter());
    store.remember(None, [vec![0.0]].into_iter());
    assert_eq!(
        store.starts(Some(&[3, 5, 7]), 3),
        vec![Some(vec![3.0]), None, Some(vec![7.0])]
    );
    store.remember(Some(&[3]), [vec![-3.0]].into_iter());
    assert_eq!(store.starts(Some(&[3]), 1), vec![Some(vec![-3.0])], "the latest wins");
    assert_eq!(store.keys(), vec![3, 7]);
    store.clear();
    assert!(store.keys().is_empty());
}

#[test]
fn quasistatic_rejects_bad_input() {
    let rest = generators::sheet(4, 1.0).unwrap();
    let layer = QuasistaticLayer::new(&rest, QuasistaticParams::default()).unwrap();
    let good = rest.flat_positions();
    let mut nan = good.clone();
    nan[4] = f64::NAN;
    let mu = ZeroLengthScaling::Global(0.1);
    assert!(matches!(
        layer.forward(&nan, &mu),
        Err(Error::NonFinite { index: 4, .. })
    ));
    assert!(matches!(
        layer.forward(&good[..6], &mu),
        Err(Error::LengthMismatch { .. })
    ));
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            layer.forward(&good, &ZeroLengthScaling::Global(bad)),
            Err(Error::InvalidParameter { .. })
        ));
    }
    let n = layer.num_vertices();
    assert!(matches!(
        layer.forward(&good, &ZeroLengthScaling::PerVertex(vec![0.1; n - 1])),
        Err(Error::LengthMismatch { .. })
    ));
    assert!(matches!(
        layer.forward(&good, &ZeroLengthScaling::PerVertex(vec![0.0; n])),
        Err(Error::InvalidParameter { .. })
    ));
    let mut neg = vec![0.1; n];
    neg[3] = -0.1;
    assert!(matches!(
        layer.forward(&good, &ZeroLengthScaling::PerVertex(neg)),
        Err(Error::InvalidParameter { .. })
    ));
    assert!(matches!(
        QuasistaticLayer::new(
            &rest,
            QuasistaticParams {
                stretch_stiffness: -1.0,
                ..QuasistaticParams::default()
            }
        ),
        Err(Error::InvalidParameter { .. })
    ));
    let (sol, _) = layer.forward(&good, &mu).unwrap();
    assert!(matches!(
        layer.backward(&sol, &good[..3]),
        Err(Error::LengthMismatch { .. })
    ));
}

#[test]
fn axial_springs_gradient_and_hessian_match_finite_differences() {
    let mut rng = TestRng::new(90);
    let rest = random_sheet(4, &mut rng);
    let shape = weft_proj::RestShape::new(&rest).unwrap();
    let axial = weft_proj::AxialSprings::new(&shape, 2.0).unwrap();
    // Zero energy at the flat rest state: the segments cross.
    assert!(axial.value(&rest.flat_positions()) < 1e-28);
    let x = predict(&rest, 1.2, 0.1, &mut rng);
    let mut grad = vec![0.0; x.len()];
    axial.add_gradient(&x, &mut grad);
    let fd = fd_gradient(|y: &[f64]| axial.value(y), &x, 1e-6);
    assert!(max_norm_rel_error(&grad, &fd) < 1e-7);
    let mut pairs = Vec::new();
    axial.hessian_pairs(&mut pairs);
    let pattern = std::sync::Arc::new(weft_linalg::SymmetricPattern::from_vertex_pairs(
        shape.num_vertices(),
        pairs,
    ));
    let mut h = weft_linalg::SymmetricMatrix::zeros(pattern);
    axial.add_hessian(&x, false, &mut h);
    let v = rng.vec(x.len(), -1.0, 1.0);
    let mut hv = vec![0.0; x.len()];
    h.mul_vec(&v, &mut hv);
    let grad_at = |y: &[f64]| {
        let mut g = vec![0.0; y.len()];
        axial.add_gradient(y, &mut g);
        g
    };
    let fd_hv = weft_testkit::fd_directional(grad_at, &x, &v, 1e-6);
    assert!(max_norm_rel_error(&hv, &fd_hv) < 1e-7);
}

#[test]
fn quasistatic_rejects_collapsed_predictions_and_saddle_equilibria() {
    // Regressions: (1) a prediction collapsed to a point "converged" at once, since springs
    // with coincident ends exert no force, at an energy maximum; (2) a flat prediction
    // compressed in its plane stays flat under Newton (no out-of-plane force ever
    // appears), ending at a saddle whose indefinite Hessian was shifted and kept, so the
    // backward pass differentiated another problem. Both are now typed errors.
    let rest = generators::sheet(6, 1.0).unwrap();
    let layer = QuasistaticLayer::new(&rest, QuasistaticParams::default()).unwrap();
    let collapsed = vec![0.25; 3 * rest.num_vertices()];
    assert!(matches!(
        layer.forward(&collapsed, &ZeroLengthScaling::Global(0.1)),
        Err(Error::CollapsedSprings { .. })
    ));
    let squeezed: Vec<f64> = rest.flat_positions().iter().map(|x| 0.6 * x).collect();
    for mu in [1.0, 0.1] {
        assert!(matches!(
            layer.forward(&squeezed, &ZeroLengthScaling::Global(mu)),
            Err(Error::NotAMinimum { .. })
        ));
    }
    // The same compression with out-of-plane noise buckles into a genuine minimum.
    let mut rng = TestRng::new(90);
    let buckled: Vec<f64> = squeezed
        .iter()
        .enumerate()
        .map(|(i, x)| if i % 3 == 2 { x + rng.uniform(-0.02, 0.02) } else { *x })
        .collect();
    assert!(layer.forward(&buckled, &ZeroLengthScaling::Global(0.1)).is_ok());
}

#[test]
fn quasistatic_backward_matches_finite_differences_on_compressed_predictions() {
    // Compressed predictions (70–85 % of rest length) with out-of-plane noise, so the
    // cloth buckles into a genuine minimum with compressed springs, where the transverse
    // spring stiffness is negative and projection and true Hessian differ.
    for (seed, sx, mu) in [(80, 0.85, 0.1), (81, 0.7, 1.0)] {
        let mut rng = TestRng::new(seed);
        let rest = random_sheet(5, &mut rng);
        let layer = QuasistaticLayer::new(&rest, tight_quasistatic()).unwrap();
        let pred = predict(&rest, sx, 0.05, &mut rng);
        let before = strain_summary(layer.rest(), &pred, 1.0).unwrap();
        assert!(
            before.min_strain < -0.1,
            "the prediction should be compressed: {before:?}"
        );
        let g = rng.vec(pred.len(), -1.0, 1.0);
        let scaling = ZeroLengthScaling::Global(mu);
        let (sol, _) = layer.forward(&pred, &scaling).unwrap();
        let grad = layer.backward(&sol, &g).unwrap();
        let loss = |x: &[f64]| {
            let (s, _) = layer.forward(x, &scaling).unwrap();
            s.positions().iter().zip(&g).map(|(a, b)| a * b).sum::<f64>()
        };
        let fd = fd_gradient(loss, &pred, 1e-6);
        let err = max_norm_rel_error(&grad.pred, &fd);
        assert!(err < 1e-4, "sx = {sx}, mu = {mu}: ∂E/∂r̂ vs FD relative error {err:e}");
    }
}

/// The stability grid's stretched prediction of a flat `sheet(n)`: scaled in-plane by
/// `1 + sx`, `1 + sy`, with noise of a tenth of the edge length in every coordinate.
fn stretched_flat(rest: &TriMesh, sx: f64, sy: f64, rng: &mut TestRng) -> Vec<f64> {
    let h = 1.0 / ((rest.num_vertices() as f64).sqrt() - 1.0);
    rest.positions()
        .iter()
        .flat_map(|p| {
            [
                (1.0 + sx) * p.x + rng.uniform(-0.05, 0.05) * h,
                (1.0 + sy) * p.y + rng.uniform(-0.05, 0.05) * h,
                rng.uniform(-0.05, 0.05) * h,
            ]
        })
        .collect()
}

#[test]
fn socp_heavy_stretch_is_polished_or_handed_over_tight() {
    // Regression (hardening defect 7): under heavy stretch the active-set polish was
    // rejected in every case below and the point returned at the IPM's default tolerance.
    // Its active-set guess called every edge active (more rows than a nearly flat sheet
    // has in-plane freedoms). Now the guess is scale-free, and the 30 %/10 % row is
    // certified by the polish at every ε. From 60 % on, 92–100 % of the edges sit at their
    // bound: the multipliers are not unique, no active-set Newton step is defined, and the
    // point is handed over after the IPM has been run to HANDOVER_TOLERANCE — with a KKT
    // residual at least 10× below the default-tolerance point's. Both are checked against
    // Clarabel at 1e-11, an independent IPM; on these degenerate problems IPMs agree only
    // to about 3e-5 (relative), which bounds what the comparison can show.
    let rest = generators::sheet(13, 1.0).unwrap();
    let mut rng = TestRng::new(31);
    for (sx, sy) in [(0.3, 0.1), (0.6, 0.6), (1.0, 1.0), (2.0, 2.0)] {
        let pred = stretched_flat(&rest, sx, sy, &mut rng);
        for eps in [0.0, 0.01, 0.1] {
            let case = format!("stretch {sx}/{sy}, ε = {eps}");
            let with = |settings: SocpSettings| {
                let layer = InextensibilityLayer::new(&rest, eps, settings).unwrap();
                layer.forward(&pred).unwrap()
            };
            let (sol, report) = with(SocpSettings::default());
            let (_, raw) = with(SocpSettings {
                polish: false,
                ..SocpSettings::default()
            });
            let (reference, _) = with(SocpSettings {
                solver: ConicSolver::Clarabel,
                tolerance: 1e-11,
                polish: false,
                ..SocpSettings::default()
            });
            assert!(report.max_violation <= 1e-9, "{case}: {report:?}");
            let err = max_norm_rel_error(sol.positions(), reference.positions());
            assert!(err < 5e-5, "{case}: {err:e} from Clarabel");
            match report.polish_iterations {
                Some(_) => assert!(report.kkt_residual < 1e-13, "{case}: polished {report:?}"),
                None => {
                    assert_eq!(report.handover_tolerance, Some(weft_proj::HANDOVER_TOLERANCE), "{case}");
                    // The hand-over continues the iteration that met the default
                    // tolerance instead of restarting it: the same iterates as a solve
                    // straight to the hand-over tolerance (a cold restart cost both solves).
                    let (straight, straight_report) = with(SocpSettings {
                        tolerance: weft_proj::HANDOVER_TOLERANCE,
                        polish: false,
                        ..SocpSettings::default()
                    });
                    assert!(
                        report.iterations <= straight_report.iterations + 1,
                        "{case}: {} iterations against {} straight to the hand-over tolerance",
                        report.iterations,
                        straight_report.iterations
                    );
                    let gap = max_norm_rel_error(sol.positions(), straight.positions());
                    assert!(gap < 1e-9, "{case}: {gap:e} from the straight tight solve");
                    assert!(
                        report.kkt_residual < 0.1 * raw.kkt_residual,
                        "{case}: handed over at KKT {:e}, default-tolerance point {:e}",
                        report.kkt_residual,
                        raw.kkt_residual
                    );
                }
            }
            if sx < 0.5 {
                assert!(
                    report.polish_iterations.is_some(),
                    "{case}: polish rejected ({report:?})"
                );
            } else {
                assert!(
                    report.active_constraints * 100 >= report.num_constraints * 92,
                    "{case}: nearly every edge should be active ({}/{})",
                    report.active_constraints,
                    report.num_constraints
                );
            }
        }
    }
}

#[test]
fn a_continuation_given_up_returns_the_default_tolerance_point_and_counts_its_iterations() {
    // The paper-size sheet under the smooth 5–30 % stretch of the `socp_moderate_stretch`
    // example: the polish is declined (more edges at their bound than in-plane freedoms)
    // and the continuation toward HANDOVER_TOLERANCE stalls on the dual residual, so the
    // point that met the default tolerance is returned. It must be that point exactly, and
    // the report must count the continuation's iterations too.
    let rest = generators::sheet(55, 1.0).unwrap();
    let mut rng = TestRng::new(5);
    let pred: Vec<f64> = rest
        .positions()
        .iter()
        .flat_map(|p| {
            let s = 1.05 + 0.25 * (0.5 + 0.5 * (3.0 * p.x + 1.0).sin() * (2.0 * p.y + 0.5).cos());
            let z = 0.05 * (4.0 * p.x).sin() * (3.0 * p.y).cos();
            [s * p.x, s * p.y, z]
        })
        .zip(std::iter::repeat_with(|| rng.uniform(-1e-3, 1e-3)))
        .map(|(v, noise)| v + noise)
        .collect();
    let run = |settings: SocpSettings| {
        InextensibilityLayer::new(&rest, 0.1, settings)
            .unwrap()
            .forward(&pred)
            .unwrap()
    };
    let (sol, report) = run(SocpSettings::default());
    let (straight, straight_report) = run(SocpSettings {
        polish: false,
        ..SocpSettings::default()
    });
    assert!(
        report.polish_iterations.is_none() && report.handover_tolerance.is_none(),
        "this case was expected to give the continuation up: {report:?}"
    );
    assert_eq!(sol.positions(), straight.positions());
    assert!(
        report.iterations > straight_report.iterations,
        "{} iterations reported, {} to the default tolerance alone",
        report.iterations,
        straight_report.iterations
    );
    assert!(report.max_violation <= 0.0, "{report:?}");
}

#[test]
fn newton_krylov_reaches_the_cholesky_equilibrium_and_gradient_cold_and_warm() {
    let mut rng = TestRng::new(70);
    let rest = random_sheet(9, &mut rng);
    let cholesky = QuasistaticLayer::new(&rest, tight_quasistatic()).unwrap();
    let krylov = QuasistaticLayer::new(
        &rest,
        QuasistaticParams {
            solver: weft_proj::QuasistaticSolver::NewtonKrylov,
            ..tight_quasistatic()
        },
    )
    .unwrap();
    let pred = predict(&rest, 1.3, 0.03, &mut rng);
    let g = rng.vec(pred.len(), -1.0, 1.0);
    for mu in [1.0, 0.1, 0.01] {
        let scaling = ZeroLengthScaling::Global(mu);
        let (a, _) = cholesky.forward(&pred, &scaling).unwrap();
        let (b, report) = krylov.forward(&pred, &scaling).unwrap();
        assert!(report.cg_iterations > 0 && report.newton.factorizations == 0);
        assert!(max_norm_rel_error(b.positions(), a.positions()) < 1e-9, "mu = {mu}");
        // The backward pass factorises at r* itself and gives the same gradients.
        let (ga, gb) = (cholesky.backward(&a, &g).unwrap(), krylov.backward(&b, &g).unwrap());
        assert!(max_norm_rel_error(&gb.pred, &ga.pred) < 1e-7, "mu = {mu}");
        assert_close!(gb.mu, ga.mu, rtol = 1e-7, atol = 1e-12);
        // A warm start from a nearby prediction's equilibrium, moved by the change of
        // prediction, reaches the same minimum in fewer Newton steps.
        let nearby: Vec<f64> = pred.iter().map(|x| x + rng.uniform(-1e-3, 1e-3)).collect();
        let (prev, _) = krylov.forward(&nearby, &scaling).unwrap();
        let start: Vec<f64> = prev
            .positions()
            .iter()
            .zip(pred.iter().zip(&nearby))
            .map(|(x, (p, q))| x + p - q)
            .collect();
        let (warm, warm_report) = krylov.forward_from(&pred, &scaling, Some(&start)).unwrap();
        assert!(max_norm_rel_error(warm.positions(), a.positions()) < 1e-9, "mu = {mu}");
        assert!(
            warm_report.newton.iterations < report.newton.iterations,
            "mu = {mu}: warm {} vs cold {} Newton steps",
            warm_report.newton.iterations,
            report.newton.iterations
        );
    }
}

#[test]
fn a_warm_started_socp_skips_the_interior_point_solve_and_finds_the_same_projection() {
    let mut rng = TestRng::new(80);
    let rest = random_sheet(9, &mut rng);
    let layer = InextensibilityLayer::new(&rest, 0.1, SocpSettings::default()).unwrap();
    let pred = predict(&rest, 1.3, 0.02, &mut rng);
    let (cold, cold_report) = layer.forward(&pred).unwrap();
    assert!(cold_report.iterations > 0);
    // One training step later: the prediction moved by a fraction of a millimetre.
    let next: Vec<f64> = pred.iter().map(|x| x + rng.uniform(-2e-4, 2e-4)).collect();
    let (reference, _) = layer.forward(&next).unwrap();
    let (warm, report) = layer.forward_from(&next, Some(&cold.warm_start())).unwrap();
    assert_eq!(report.iterations, 0, "the interior-point solve ran: {report:?}");
    assert!(report.polish_iterations.is_some());
    assert!(max_norm_rel_error(warm.positions(), reference.positions()) < 1e-9);
    // The backward passes agree too.
    let g = rng.vec(pred.len(), -1.0, 1.0);
    let (a, b) = (
        layer.backward(&reference, &g).unwrap(),
        layer.backward(&warm, &g).unwrap(),
    );
    assert!(max_norm_rel_error(&b, &a) < 1e-7);
    // A start from a far-away problem still ends at the right projection (via the cold
    // solve if the polish cannot certify it).
    let far = predict(&rest, 1.0, 0.0, &mut rng);
    let (far_solution, _) = layer.forward(&far).unwrap();
    let (again, _) = layer.forward_from(&next, Some(&far_solution)).unwrap();
    assert!(max_norm_rel_error(again.positions(), reference.positions()) < 1e-9);
}
