//! NNWarp's runtime against the full nonlinear FEM it stands in for, in one run
//! (NNWarp Table 1): on the 637-node training beam and the ~50 k-tet limb body,
//! - one plain pre-factorised linear solve (the baseline);
//! - one NNWarp frame (`NnWarpSimulation::step`: loads rotated into the rest frames, the
//!   solve, the node-wise correction);
//! - the correction alone;
//! - one Neo-Hookean implicit-Euler frame.
//!
//! The network has the paper's shape (2 × 16 tanh) with seeded weights: its time does not
//! depend on their values.

use std::cell::RefCell;

use criterion::{Criterion, criterion_group, criterion_main};
use weft_mesh::TetMesh;
use weft_nn::nnwarp::{NnWarpSimulation, Standardization, WarpBody, WarpMlp, hidden_layers};
use weft_nn::params::ParamStore;
use weft_sim::energies::{ConstantForce, LameParameters, Material, TetElasticity};
use weft_sim::warp::FieldDirection;
use weft_sim::{Energy, ImplicitEuler, LinearSolve, PrefactorizedLinear};

/// A Neo-Hookean-shaped network with seeded weights and a plausible standardisation.
fn network() -> weft_nn::nnwarp::NodeMlp {
    let rows: Vec<[f64; 7]> = (0..64)
        .map(|k| std::array::from_fn(|d| ((k * 7 + d) % 11) as f64 / 5.0 - 1.0))
        .collect();
    let outs: Vec<[f64; 3]> = (0..64)
        .map(|k| std::array::from_fn(|d| ((k * 3 + d) % 7) as f64 / 50.0))
        .collect();
    let standardization = Standardization::fit(&rows, &outs).unwrap();
    let mut params = ParamStore::new(&weft_nn::Device::Cpu, 1);
    let mlp = WarpMlp::new(&mut params, &hidden_layers("neo-hookean"), &standardization).unwrap();
    mlp.to_node_mlp(standardization).unwrap()
}

fn body(c: &mut Criterion, name: &str, mesh: TetMesh, anchors: Vec<usize>) {
    let lame = LameParameters::from_young_poisson(1e5, 0.3).unwrap();
    let linear_energy = TetElasticity::new(&mesh, Material::Linear, lame).unwrap();
    let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), 1000.0);
    let fixed = weft_sim::anchors::fixed_dofs(mesh.num_vertices(), &anchors).unwrap();
    let rest = mesh.flat_positions();
    let gravity = ConstantForce::gravity(&masses, [0.0, -9.81, 0.0]).unwrap();
    let forces = gravity.forces().to_vec();
    let linear = RefCell::new(
        PrefactorizedLinear::new(
            &rest,
            &[&linear_energy],
            masses.clone(),
            fixed.clone(),
            LinearSolve::Static,
        )
        .unwrap(),
    );
    let runtime = RefCell::new(
        NnWarpSimulation::from_body(
            WarpBody {
                mesh: &mesh,
                anchors: &anchors,
                young: 1e5,
                poisson: 0.3,
                density: 1000.0,
                forces: &forces,
                // Static like the baseline (every frame after the first carries the full load),
                // so the two differ only by NNWarp's work.
                solve: LinearSolve::Static,
                field: FieldDirection::Directional(-nalgebra::Vector3::y()),
                frames: 1,
            },
            network(),
        )
        .unwrap(),
    );
    let terms: Vec<Box<dyn Energy>> = vec![
        Box::new(TetElasticity::new(&mesh, Material::NeoHookean, lame).unwrap()),
        Box::new(gravity),
    ];
    let full = RefCell::new(ImplicitEuler::new(masses, 0.01, rest, terms, fixed).unwrap());
    let mut group = c.benchmark_group(format!("nnwarp-{name}-{}-tets", mesh.num_tets()));
    group.sample_size(10);
    group.bench_function("linear solve", |b| {
        b.iter(|| linear.borrow_mut().step(&forces, &[]).unwrap())
    });
    group.bench_function("NNWarp frame (rest-frame loads, solve, correction)", |b| {
        b.iter(|| runtime.borrow_mut().step().unwrap())
    });
    group.bench_function("NNWarp correction alone", |b| {
        let u = linear.borrow().displacements().to_vec();
        // The runtime's own corrector, not a second one built beside it.
        let runtime = runtime.borrow();
        b.iter(|| runtime.warp().warp(&u).unwrap())
    });
    group.bench_function("full Neo-Hookean frame (implicit Euler)", |b| {
        b.iter(|| full.borrow_mut().step(&[]).unwrap())
    });
    group.finish();
}

fn nnwarp(c: &mut Criterion) {
    let beam = weft_mesh::generators::beam(&weft_mesh::generators::BeamParams::default()).unwrap();
    let clamped: Vec<usize> = (0..beam.num_vertices())
        .filter(|&i| beam.positions()[i].x.abs() < 1e-12)
        .collect();
    body(c, "beam", beam, clamped);
    let limb = weft_mesh::limb::limb(&weft_sim::scenes::volume::LimbResolution::Benchmark.params()).unwrap();
    let bones = limb.all_bone_nodes();
    body(c, "limb", limb.mesh, bones);
}

criterion_group!(benches, nnwarp);
criterion_main!(benches);
