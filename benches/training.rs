//! Training cost per step of the learned models on the candle autograd path, the path the
//! one trainer runs today (issue "Training faster than PyTorch"):
//! - one Alt-ConvLSTM sequence pass — 20 teacher-forced steps, full backpropagation, one
//!   Adam step, batch 1 — on the 1410-vertex `limb` surface (the standard dataset's) and the
//!   6890-vertex one (SMPL's vertex count), widths 32-64-128-64-32;
//! - one embedding stage-1 step on the 4225-vertex sheet (`sheet-ms` at standard size): a
//!   batch of 8 windows through the encoder, decoder, ACAP⁻¹ and `L_phys`, backward, Adam;
//!   and, for both models, the forward pass and loss alone and with the backward pass, so
//!   the rows split a step into forward, backward and Adam.
//!
//! The frames are synthetic (a skin swinging a few millimetres, the tissue lagging it): the
//! cost does not depend on their values. The anchor a user compares against — the same
//! Alt-ConvLSTM pass in PyTorch 2.15 on this CPU, 0.75 s — is in docs/BENCHMARKS.md.

use criterion::{Criterion, criterion_group, criterion_main};
use weft_nn::adam::{Adam, AdamSettings};
use weft_nn::altconv::{AltConvNet, AltConvTraining, HIDDEN, Kernels, SequenceTensors, TrainingPath, Variant};
use weft_nn::graph::NormalizedAdjacency;
use weft_nn::params::ParamStore;
use weft_nn::trainer::{BatchAt, BatchLoss, Trainable};
use weft_sim::scenes::soft_tissue::{SoftTissue, SoftTissueParams};

// The allocator `cargo xtask` trains with: the bench measures what a user's run costs.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

const STEPS: usize = 20;

/// The loss tensor of `model` on `batch`, as the trainer's first batch of an epoch (a
/// macro so the bench need not name candle's tensor type: only weft-nn depends on candle).
macro_rules! loss_on {
    ($model:expr, $batch:expr) => {{
        let at = BatchAt {
            epoch: 0,
            batch: 0,
            batches: 1,
        };
        match $model.batch_loss($batch, at).unwrap() {
            BatchLoss::Loss { loss, .. } => loss,
            BatchLoss::Skipped { .. } => panic!("the batch was skipped"),
        }
    }};
}

/// One training step of `model` on `batch`: loss, backward, Adam on every group.
fn step(model: &mut dyn Trainable, adams: &mut [Adam], batch: &[usize]) {
    let grads = loss_on!(model, batch).backward().unwrap();
    for (g, adam) in model.groups().iter().zip(adams.iter_mut()) {
        adam.step(g.params, &grads).unwrap();
    }
}

fn altconv_pass(c: &mut Criterion, limb: weft_mesh::limb::LimbParams, vertices: usize) {
    let body = SoftTissue::new(weft_mesh::limb::limb(&limb).unwrap(), SoftTissueParams::default()).unwrap();
    let surface = body.surface().mesh.clone();
    assert_eq!(surface.num_vertices(), vertices);
    let adj = NormalizedAdjacency::new(&surface).unwrap();
    let (x0, y0) = (body.skinned_surface(), body.simulated_surface());
    let frame = |base: &[f64], t: usize, lag: f64| -> Vec<f64> {
        let s = 3e-3 * ((t as f64 - lag) * 0.3).sin();
        base.iter()
            .enumerate()
            .map(|(i, v)| v + if i % 3 == 1 { s } else { 0.0 })
            .collect()
    };
    let seq = weft_data::LimbSequence {
        index: 0,
        split: "train".into(),
        skinned: (0..=STEPS).map(|t| frame(&x0, t, 0.0)).collect(),
        simulated: (0..=STEPS).map(|t| frame(&y0, t, 1.5)).collect(),
    };
    let data = vec![SequenceTensors::new(&seq, STEPS + 1, &weft_nn::Device::Cpu).unwrap()];
    let mut params = ParamStore::new(&weft_nn::Device::Cpu, 3);
    let net = AltConvNet::new(&mut params, Variant::Alt, &HIDDEN).unwrap();
    let settings = AdamSettings::default();
    let mut adams = vec![Adam::new(&params, settings).unwrap()];
    let training = |path: TrainingPath| AltConvTraining {
        net: &net,
        params: &params,
        adj: &adj,
        train: &data,
        validation: &data,
        steps: STEPS,
        adam: settings,
        recipe: weft_nn::altconv::Recipe::default(),
        seed: 0,
        path,
    };
    let mut group = c.benchmark_group(format!("training-altconv-{vertices}"));
    group.sample_size(10);
    let loss = |model: &mut AltConvTraining<'_>| loss_on!(model, &[0]);
    for (name, path) in [
        ("fused", TrainingPath::new(Kernels::Fused)),
        ("candle autograd", TrainingPath::new(Kernels::Autograd)),
    ] {
        let mut model = training(path);
        group.bench_function(format!("sequence pass ({name})"), |b| {
            b.iter(|| step(&mut model, &mut adams, &[0]))
        });
        // Where the pass goes: the forward pass and loss alone, then with the backward pass.
        group.bench_function(format!("forward and loss ({name})"), |b| b.iter(|| loss(&mut model)));
        group.bench_function(format!("forward, loss and backward ({name})"), |b| {
            b.iter(|| loss(&mut model).backward().unwrap())
        });
    }
    group.finish();
}

fn altconv(c: &mut Criterion) {
    altconv_pass(c, weft_mesh::limb::LimbParams::default(), 1410);
    altconv_pass(c, weft_mesh::limb::LimbParams::smpl_resolution(), 6890);
}

fn embedding(c: &mut Criterion) {
    use weft_nn::embed::{EmbedData, EmbedModel, EmbedStage, EmbedTrainingSettings};
    use weft_sim::ClothScene;
    // Three simulated frames of the standard sheet: one training window.
    let scene = ClothScene::builtin("sheet-ms", false).unwrap();
    let dataset = weft_data::ClothDataset::simulate("sheet-ms", scene, 3).unwrap();
    assert_eq!(dataset.rest.num_vertices(), 4225);
    let data = EmbedData::new(dataset).unwrap();
    let mut group = c.benchmark_group("training-embed-4225");
    group.sample_size(10);
    for (name, kernels) in [
        ("fused", weft_nn::Kernels::Fused),
        ("candle autograd", weft_nn::Kernels::Autograd),
    ] {
        let config = EmbedTrainingSettings {
            kernels,
            ..Default::default()
        };
        let model = EmbedModel::new(config.clone(), &data).unwrap();
        let mut adams = vec![Adam::new(&model.autoencoder_params, config.adam).unwrap()];
        let mut stage = EmbedStage::new(&model, &data, 1);
        group.bench_function(format!("stage-1 step, 8 windows ({name})"), |b| {
            b.iter(|| step(&mut stage, &mut adams, &[0; 8]))
        });
        // Where the step goes: the losses alone, then with the backward pass (the rest of
        // the step is Adam over 9.8 M parameters).
        let loss = |stage: &mut EmbedStage<'_>| loss_on!(stage, &[0; 8]);
        group.bench_function(format!("forward and loss, 8 windows ({name})"), |b| {
            b.iter(|| loss(&mut stage))
        });
        group.bench_function(format!("forward, loss and backward, 8 windows ({name})"), |b| {
            b.iter(|| loss(&mut stage).backward().unwrap())
        });
    }
    group.finish();
}

/// One NNWarp Adam step (a batch of 1024 node pairs, the default) with the Neo-Hookean
/// network, on candle's autograd: the standard dataset's epoch is about a thousand of them,
/// the paper size's about thirteen thousand. (A fused op for this 7-16-16-3 network was
/// only marginally faster and not kept: the step is not the network's arithmetic.)
fn nnwarp(c: &mut Criterion) {
    use weft_nn::nnwarp::{INPUTS, Standardization, WarpMlp, WarpTraining, hidden_layers, pair_tensors};
    let mut rng = weft_sim::rng::SplitMix64::new(5);
    let n = 8192;
    let rows: Vec<[f64; INPUTS]> = (0..n)
        .map(|_| std::array::from_fn(|_| rng.uniform(-2.0, 2.0)))
        .collect();
    let outs: Vec<[f64; 3]> = (0..n)
        .map(|_| std::array::from_fn(|_| rng.uniform(-0.3, 0.3)))
        .collect();
    let standardization = Standardization::fit(&rows, &outs).unwrap();
    let (x, y) = pair_tensors(&rows, &outs, &standardization, &weft_nn::Device::Cpu).unwrap();
    let batch: Vec<usize> = (0..1024).map(|k| (k * 7) % n).collect();
    let mut group = c.benchmark_group("training-nnwarp");
    let mut params = ParamStore::new(&weft_nn::Device::Cpu, 1);
    let mlp = WarpMlp::new(&mut params, &hidden_layers("neo-hookean"), &standardization).unwrap();
    let settings = AdamSettings::default();
    let mut adams = vec![Adam::new(&params, settings).unwrap()];
    let mut model = WarpTraining {
        mlp: &mlp,
        params: &params,
        x: &x,
        y: &y,
        validation_x: &x,
        validation_y: &y,
        adam: settings,
    };
    group.bench_function("step, 1024 node pairs (candle autograd)", |b| {
        b.iter(|| step(&mut model, &mut adams, &batch))
    });
    group.finish();
}

criterion_group!(benches, altconv, embedding, nnwarp);
criterion_main!(benches);
