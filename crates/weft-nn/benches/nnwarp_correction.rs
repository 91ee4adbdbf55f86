//! NNWarp's network on the 637 free-node batch of the training beam, in candle against the
//! runtime's own evaluation of the same weights (faer products, f32), as the issue asks:
//! "measure both and keep the faster". Both evaluate the network twice, at the inputs and
//! at rest (`net(x) − net(x₀)`), as `WarpMlp::forward` does.

use candle_core::{Device, Tensor};
use criterion::{Criterion, criterion_group, criterion_main};
use weft_nn::nnwarp::{INPUTS, Standardization, WarpMlp, hidden_layers};
use weft_nn::params::ParamStore;

fn correction(c: &mut Criterion) {
    let n = 637;
    let rows: Vec<[f64; INPUTS]> = (0..n)
        .map(|k| std::array::from_fn(|d| ((k * 7 + d) % 11) as f64 / 5.0 - 1.0))
        .collect();
    let outs: Vec<[f64; 3]> = (0..n)
        .map(|k| std::array::from_fn(|d| ((k * 3 + d) % 7) as f64 / 50.0))
        .collect();
    let standardization = Standardization::fit(&rows, &outs).unwrap();
    let mut params = ParamStore::new(&Device::Cpu, 1);
    let mlp = WarpMlp::new(&mut params, &hidden_layers("neo-hookean"), &standardization).unwrap();
    let node = mlp.to_node_mlp(standardization.clone()).unwrap();
    let x: Vec<f32> = rows
        .iter()
        .flat_map(|r| standardization.input(r).map(|v| v as f32))
        .collect();
    let tensor = Tensor::from_vec(x.clone(), (n, INPUTS), &Device::Cpu).unwrap();
    // Column-major, as the runtime lays its batch out.
    let xs = &x;
    let columns: Vec<f32> = (0..INPUTS)
        .flat_map(|d| (0..n).map(move |k| xs[k * INPUTS + d]))
        .collect();
    let mut group = c.benchmark_group("nnwarp-network-637-nodes");
    group.bench_function("candle (WarpMlp::forward)", |b| {
        b.iter(|| mlp.forward(&tensor).unwrap())
    });
    group.bench_function("runtime (NodeMlp::net_batch, twice)", |b| {
        b.iter(|| (node.net_batch(&columns, n), node.net_batch(&columns, n)))
    });
    group.finish();
}

criterion_group!(benches, correction);
criterion_main!(benches);
