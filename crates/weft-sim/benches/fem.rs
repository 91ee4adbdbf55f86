//! Volumetric FEM timings behind NNWarp Table 1: the pre-factorised linear system
//! (factorise once, one solve per step) against a full Neo-Hookean implicit-Euler step
//! (Newton, re-assembled and re-factorised every iteration), on the default beam
//! (2592 tets) and the ~50k-tet benchmark limb (50 400 tets). See `benches/README.md`.

use std::sync::Arc;

use criterion::{Criterion, criterion_group, criterion_main};
use weft_linalg::{CholeskySolver, Substructuring, SymmetricMatrix, SymmetricPattern};
use weft_mesh::TetMesh;
use weft_mesh::generators::{BeamParams, beam};
use weft_mesh::limb::{LimbParams, limb};
use weft_sim::anchors::{fixed_dofs, hold, nodes_at_min};
use weft_sim::energies::{ConstantForce, LameParameters, Material, TetElasticity};
use weft_sim::{Energy, ImplicitEuler, LinearSolve, PrefactorizedLinear, RayleighDamping};

const DT: f64 = 0.01;

struct Case {
    name: &'static str,
    mesh: TetMesh,
    masses: Vec<f64>,
    anchors: Vec<usize>,
    fixed: Vec<bool>,
    gravity: ConstantForce,
}

fn case(name: &'static str, mesh: TetMesh) -> Case {
    let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), 1000.0);
    let anchors = nodes_at_min(mesh.positions(), 0, 1e-9).unwrap();
    let fixed = fixed_dofs(mesh.num_vertices(), &anchors).unwrap();
    let gravity = ConstantForce::gravity(&masses, [0.0, 0.0, -9.81]).unwrap();
    Case {
        name,
        mesh,
        masses,
        anchors,
        fixed,
        gravity,
    }
}

fn lame() -> LameParameters {
    LameParameters::from_young_poisson(1e5, 0.45).unwrap()
}

fn bench_case(c: &mut Criterion, case: &Case, nonlinear_samples: usize) {
    let rest = case.mesh.flat_positions();
    let linear = TetElasticity::new(&case.mesh, Material::Linear, lame()).unwrap();
    let mut group = c.benchmark_group(format!("fem/{}", case.name));
    // Factorisation of the constant system matrix M/Δt² + K (anchors eliminated):
    // symbolic analysis + numeric Cholesky, as NNWarp's "Factorization" column.
    {
        let mut pairs = Vec::new();
        linear.hessian_pairs(&mut pairs);
        let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(case.mesh.num_vertices(), pairs));
        let mut system = SymmetricMatrix::zeros(pattern.clone());
        linear.add_hessian(&rest, false, &mut system);
        for (i, m) in case.masses.iter().enumerate() {
            for k in 0..3 {
                system.add(3 * i + k, 3 * i + k, m / (DT * DT));
            }
        }
        system.constrain_dofs(&case.fixed);
        // Default: two domains on two threads when the body splits well (weft-linalg's
        // `Substructuring::Auto`); `one thread`: the undivided sequential factor, as a
        // same-run baseline.
        for (label, sub) in [("", Substructuring::Auto), (", one thread", Substructuring::Never)] {
            group.bench_function(format!("prefactorized linear: factorisation{label}"), |b| {
                b.iter(|| {
                    let solver = CholeskySolver::with_substructuring(pattern.clone(), sub).unwrap();
                    solver.factorize(&system).unwrap()
                })
            });
            // The numeric part alone (the symbolic analysis is reusable across materials
            // and time steps on the same mesh).
            let solver = CholeskySolver::with_substructuring(pattern.clone(), sub).unwrap();
            eprintln!(
                "{}{label}: {} DOFs, {} stored entries in A (upper), {} in L, {} domain(s)",
                case.name,
                pattern.dim(),
                pattern.nnz(),
                solver.factor_nnz(),
                solver.domains()
            );
            group.bench_function(format!("prefactorized linear: numeric factorisation{label}"), |b| {
                b.iter(|| solver.factorize(&system).unwrap())
            });
            let factor = solver.factorize(&system).unwrap();
            let rhs: Vec<f64> = (0..pattern.dim()).map(|i| (0.1 * i as f64).sin()).collect();
            group.bench_function(format!("prefactorized linear: solve{label}"), |b| {
                b.iter(|| {
                    let mut x = rhs.clone();
                    factor.solve_in_place(&mut x);
                    x
                })
            });
        }
    }
    // One pre-factorised step: right-hand side + one sparse solve.
    let mut pre = PrefactorizedLinear::new(
        &rest,
        &[&linear],
        case.masses.clone(),
        case.fixed.clone(),
        LinearSolve::Dynamic {
            dt: DT,
            damping: RayleighDamping::NONE,
        },
    )
    .unwrap();
    group.bench_function("prefactorized linear: step", |b| {
        b.iter(|| pre.step(case.gravity.forces(), &[]).unwrap())
    });
    // One full Neo-Hookean implicit-Euler step (Newton to convergence).
    let nh = TetElasticity::new(&case.mesh, Material::NeoHookean, lame()).unwrap();
    let mut ie = ImplicitEuler::new(
        case.masses.clone(),
        DT,
        rest.clone(),
        vec![Box::new(nh), Box::new(case.gravity.clone())],
        case.fixed.clone(),
    )
    .unwrap();
    let prescribed = hold(&case.anchors, &rest);
    group.sample_size(nonlinear_samples);
    group.bench_function("neo-hookean implicit euler: step", |b| {
        b.iter(|| ie.step(&prescribed).unwrap())
    });
    group.finish();
}

fn beam_2592(c: &mut Criterion) {
    let mesh = beam(&BeamParams::default()).unwrap();
    assert_eq!(mesh.num_tets(), 2592);
    bench_case(c, &case("beam-2592", mesh), 20);
}

fn body_50k(c: &mut Criterion) {
    let mesh = limb(&LimbParams::benchmark()).unwrap().mesh;
    assert_eq!(mesh.num_tets(), 50_400);
    bench_case(c, &case("limb-50400", mesh), 10);
}

criterion_group! {
    name = small;
    config = Criterion::default();
    targets = beam_2592
}
criterion_group! {
    name = large;
    config = Criterion::default().sample_size(10);
    targets = body_50k
}
criterion_main!(small, large);
