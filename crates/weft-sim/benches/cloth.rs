//! Ground-truth cost per frame of the full-size built-in cloth scenes (Tan et al.'s
//! SHEET and BALL resolutions): one implicit-Euler step, including Newton iterations.
//! Prints the mean Newton iterations per frame over all frames the bench ran.

use std::cell::RefCell;

use criterion::{Criterion, criterion_group, criterion_main};
use weft_sim::{ClothScene, ClothSimulation};

fn frames(c: &mut Criterion) {
    let mut group = c.benchmark_group("cloth-frame");
    group.sample_size(10);
    for name in ["sheet-ms", "sheet-fem", "ball-fem"] {
        let sim = RefCell::new(ClothSimulation::new(ClothScene::builtin(name, false).unwrap(), None).unwrap());
        // Leave the rest state first: the first frames start the motion.
        for _ in 0..3 {
            sim.borrow_mut().step().unwrap();
        }
        let iterations = RefCell::new((0usize, 0usize));
        group.bench_function(name, |b| {
            b.iter(|| {
                let f = sim.borrow_mut().step().unwrap();
                let mut it = iterations.borrow_mut();
                it.0 += f.report.newton.iterations;
                it.1 += 1;
            })
        });
        let (total, n) = *iterations.borrow();
        eprintln!(
            "{name}: {:.2} Newton iterations per frame over {n} frames",
            total as f64 / n.max(1) as f64
        );
    }
    group.finish();
}

criterion_group!(benches, frames);
criterion_main!(benches);
