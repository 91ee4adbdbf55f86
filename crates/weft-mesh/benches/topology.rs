//! Topology construction on the paper-size meshes: the 4225-vertex sheet (Tan et al.'s
//! SHEET) and the default 2592-tet beam.

use criterion::{Criterion, criterion_group, criterion_main};
use weft_mesh::{TetTopology, Topology, generators};

fn topology(c: &mut Criterion) {
    let sheet = generators::sheet(65, 1.0).unwrap();
    c.bench_function("topology/sheet-65 (4225 vertices)", |b| {
        b.iter(|| Topology::new(&sheet))
    });
    let beam = generators::beam(&generators::BeamParams::default()).unwrap();
    c.bench_function("topology/beam (2592 tets)", |b| b.iter(|| TetTopology::new(&beam)));
    c.bench_function("boundary-surface/beam (2592 tets)", |b| {
        b.iter(|| beam.boundary_surface().unwrap())
    });
}

criterion_group!(benches, topology);
criterion_main!(benches);
