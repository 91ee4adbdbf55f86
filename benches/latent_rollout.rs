//! Tan et al.'s learned simulator against the ground truth it replaces, in one run, on the
//! 4225-vertex `sheet-ms`: one implicit-Euler frame versus one latent roll-out frame
//! decoded all the way to vertex positions (latent MLP step, decoder, ACAP⁻¹), and each
//! stage of the latter alone. The network has the paper's shape (128-D latent, two graph
//! convolutions, a 256-256 latent MLP) with seeded weights: its time does not depend on
//! their values.

use std::cell::RefCell;
use std::sync::Arc;

use criterion::{Criterion, criterion_group, criterion_main};
use weft_acap::{AcapFeatures, AcapSettings, FeatureNormalization, PoissonPseudoInverse};
use weft_mesh::unflatten;
use weft_nn::embed::LatentRollout;
use weft_nn::embed::{AutoencoderSettings, LatentSimulator, LatentSimulatorSettings, MeshAutoencoder};
use weft_nn::graph::MeshGraph;
use weft_nn::params::ParamStore;
use weft_sim::{ClothScene, ClothSimulation};

fn latent_rollout(c: &mut Criterion) {
    let sim = RefCell::new(ClothSimulation::new(ClothScene::builtin("sheet-ms", false).unwrap(), None).unwrap());
    // Past the wrinkling first frames, into the sequence's ordinary frames.
    for _ in 0..10 {
        sim.borrow_mut().step().unwrap();
    }
    let mesh = sim.borrow().mesh().clone();
    let pins = sim.borrow().grasp_vertices().to_vec();
    let frame = unflatten(sim.borrow().integrator().positions());
    let q: Vec<f64> = pins
        .iter()
        .flat_map(|&i| [frame[i].x, frame[i].y, frame[i].z])
        .collect();
    let features = AcapFeatures::new(&mesh, AcapSettings::default()).unwrap();
    let encoded = features.encode(&frame).unwrap();
    let normalization = FeatureNormalization::fit_per_block(encoded.iter()).unwrap();
    let inverse = Arc::new(PoissonPseudoInverse::new(&features, &pins).unwrap());
    // The CPU device, re-exported by weft-nn (the benches do not depend on candle).
    let device = weft_nn::Device::Cpu;
    let graph = Arc::new(MeshGraph::new(&mesh, &device).unwrap());
    let mut params = ParamStore::new(&device, 1);
    let ae = MeshAutoencoder::new(&mut params, graph, AutoencoderSettings::default()).unwrap();
    let latent_sim = LatentSimulator::new(
        &mut params,
        LatentSimulatorSettings {
            latent: 128,
            controls: q.len(),
            hidden: vec![256, 256],
        },
    )
    .unwrap();
    let z = vec![0.0; 128];
    let rollout =
        RefCell::new(LatentRollout::new(&ae, &latent_sim, inverse.clone(), normalization.clone(), &z, &z).unwrap());
    // Where a roll-out frame's time goes, averaged over 50 frames.
    let mut total = weft_nn::embed::FrameProfile::default();
    // Each frame is one step from the same two codes: with untrained weights a long
    // recurrent roll-out grows without bound (and the NaN guard stops it).
    for _ in 0..50 {
        rollout.borrow_mut().restart(&z, &z).unwrap();
        let (_, p) = rollout.borrow_mut().step_profiled(&q).unwrap();
        total.latent_step += p.latent_step;
        total.decoder += p.decoder;
        if total.decoder_layers.is_empty() {
            total.decoder_layers = vec![std::time::Duration::ZERO; p.decoder_layers.len()];
        }
        for (a, d) in total.decoder_layers.iter_mut().zip(&p.decoder_layers) {
            *a += *d;
        }
        total.rotations += p.rotations;
        total.solve += p.solve;
    }
    eprintln!(
        "roll-out frame profile (mean of 50): latent MLP {:?}, decoder {:?} (fully connected, then each graph \
         convolution: {:?}), Rodrigues and T = RS {:?}, Poisson solve {:?}",
        total.latent_step / 50,
        total.decoder / 50,
        total.decoder_layers.iter().map(|d| *d / 50).collect::<Vec<_>>(),
        total.rotations / 50,
        total.solve / 50
    );

    let mut group = c.benchmark_group("sheet-ms-4225-rollout");
    group.sample_size(10);
    group.bench_function("ground-truth frame (implicit Euler)", |b| {
        b.iter(|| sim.borrow_mut().step().unwrap())
    });
    group.bench_function("latent roll-out frame (MLP + decoder + ACAP⁻¹)", |b| {
        b.iter(|| {
            let mut r = rollout.borrow_mut();
            r.restart(&z, &z).unwrap();
            r.step(&q).unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, latent_rollout);
criterion_main!(benches);
