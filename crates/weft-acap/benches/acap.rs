//! Per-frame cost of ACAP encode and decode on Tan et al.'s 4225-vertex sheet, and the
//! one-time setup (precomputation + Cholesky factorisation) per rest mesh and pin set.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;
use std::hint::black_box;
use weft_acap::{AcapFeatures, AcapSettings, PoissonPseudoInverse};

fn twisted_sheet() -> (weft_mesh::TriMesh, Vec<Vector3<f64>>) {
    let rest = weft_mesh::generators::sheet(65, 1.0).expect("sheet");
    let total = 200f64.to_radians();
    let p = rest
        .positions()
        .iter()
        .map(|q| {
            let a = total * (q.x + 0.5);
            Vector3::new(q.x, q.y * a.cos(), q.y * a.sin())
        })
        .collect();
    (rest, p)
}

fn bench(c: &mut Criterion) {
    let (rest, p) = twisted_sheet();
    let pins = [0, 64];
    let pin_xyz = [p[0], p[64]];
    let acap = AcapFeatures::new(&rest, AcapSettings::default()).expect("extractor");
    let inverse = PoissonPseudoInverse::new(&acap, &pins).expect("factorisation");
    let features = acap.encode(&p).expect("encode");
    let grad = vec![Vector3::new(0.1, -0.2, 0.3); p.len()];

    c.bench_function("acap/setup_extractor_sheet65", |b| {
        b.iter(|| AcapFeatures::new(black_box(&rest), AcapSettings::default()).unwrap())
    });
    c.bench_function("acap/setup_factorize_sheet65", |b| {
        b.iter(|| PoissonPseudoInverse::new(black_box(&acap), &pins).unwrap())
    });
    c.bench_function("acap/encode_sheet65", |b| {
        b.iter(|| acap.encode(black_box(&p)).unwrap())
    });
    c.bench_function("acap/decode_sheet65", |b| {
        b.iter(|| inverse.decode(black_box(&features), &pin_xyz).unwrap())
    });
    c.bench_function("acap/vjp_sheet65", |b| {
        b.iter(|| inverse.vjp(black_box(&features), &grad).unwrap())
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
