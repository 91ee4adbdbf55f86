//! Alt-ConvLSTM's roll-out frame on the 6890-vertex limb surface (the SMPL body's vertex
//! count, seed 001 §5.2: 22 FPS on a Titan RTX), against the Neo-Hookean ground truth's
//! frame of the same body measured in the same run.
//!
//! The network has the paper's shape (32-64-128-64-32 hidden channels, 3 out) with
//! seeded weights; its time does not depend on their values. A frame is one
//! `AltConvRuntime::step`: the normalised-adjacency products, the gate matrix products
//! and the fused state updates of all six cells. The ground-truth frame (two
//! implicit-Euler substeps of the 136 k-tet body, about a minute) is timed twice outside
//! criterion, whose minimum of ten samples would take twenty minutes, and printed.

use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use weft_nn::altconv::{AltConvNet, AltConvRuntime, HIDDEN, Variant};
use weft_nn::graph::NormalizedAdjacency;
use weft_nn::params::ParamStore;
use weft_sim::scenes::soft_tissue::{SoftTissue, SoftTissueParams};

fn altconv(c: &mut Criterion) {
    let limb = weft_mesh::limb::limb(&weft_mesh::limb::LimbParams::smpl_resolution()).unwrap();
    let mut body = SoftTissue::new(limb, SoftTissueParams::default()).unwrap();
    let surface = body.surface().mesh.clone();
    assert_eq!(surface.num_vertices(), 6890);
    let adj = NormalizedAdjacency::new(&surface).unwrap();
    let x0 = body.skinned_surface();
    let y0 = body.simulated_surface();
    let mut group = c.benchmark_group("altconv-limb-6890");
    group.sample_size(10);
    for variant in [Variant::Alt, Variant::NpY] {
        let mut params = ParamStore::new(&weft_nn::Device::Cpu, 3);
        let net = AltConvNet::new(&mut params, variant, &HIDDEN).unwrap();
        let mut runtime = AltConvRuntime::new(&net, adj.clone()).unwrap();
        runtime.start(&x0, &y0).unwrap();
        // The skin swinging a little, frame after frame.
        let mut t = 0usize;
        group.bench_function(format!("{} roll-out frame", variant.name()), |b| {
            b.iter(|| {
                t += 1;
                let s = 1e-3 * (t as f64 * 0.1).sin();
                let x: Vec<f64> = x0.iter().map(|v| v + s).collect();
                runtime.step(&x).unwrap()
            })
        });
    }
    group.finish();
    let mut seconds = Vec::new();
    for _ in 0..2 {
        let start = Instant::now();
        body.step_frame().unwrap();
        seconds.push(start.elapsed().as_secs_f64());
    }
    println!(
        "altconv-limb-6890/Neo-Hookean ground-truth frame: {:.2} s and {:.2} s ({} tets)",
        seconds[0],
        seconds[1],
        body.limb().mesh.num_tets()
    );
}

criterion_group!(benches, altconv);
criterion_main!(benches);
