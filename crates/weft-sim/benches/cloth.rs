//! Ground-truth cost per frame of the full-size built-in cloth scenes (Tan et al.'s
//! SHEET and BALL resolutions): one implicit-Euler step, including Newton iterations,
//! with the scene's line search and, for the sheets, with the trust region
//! (`<scene>/trust-region`). Prints the mean Newton and conjugate-gradient iterations,
//! factorisations and diagonally shifted refactorisations per frame over all frames the
//! bench ran.

use std::cell::RefCell;

use criterion::{Criterion, criterion_group, criterion_main};
use weft_sim::{ClothScene, ClothSimulation, Globalization};

fn frames(c: &mut Criterion) {
    let mut group = c.benchmark_group("cloth-frame");
    group.sample_size(10);
    let rows = [
        ("sheet-ms", Globalization::LineSearch),
        ("sheet-ms", Globalization::TrustRegion),
        ("sheet-fem", Globalization::LineSearch),
        ("sheet-fem", Globalization::TrustRegion),
        ("ball-fem", Globalization::LineSearch),
    ];
    for (name, globalization) in rows {
        let mut scene = ClothScene::builtin(name, false).unwrap();
        scene.globalization = Some(globalization);
        let sim = RefCell::new(ClothSimulation::new(scene, None).unwrap());
        // Leave the rest state first: the first frames start the motion.
        for _ in 0..3 {
            sim.borrow_mut().step().unwrap();
        }
        let counts = RefCell::new([0usize; 5]);
        let row = match globalization {
            Globalization::LineSearch => name.to_string(),
            Globalization::TrustRegion => format!("{name}/trust-region"),
        };
        group.bench_function(&row, |b| {
            b.iter(|| {
                let f = sim.borrow_mut().step().unwrap();
                let mut n = counts.borrow_mut();
                n[0] += f.report.newton.iterations;
                n[1] += f.report.newton.cg_iterations;
                n[2] += f.report.newton.factorizations;
                n[3] += 1;
                n[4] += f.report.newton.regularizations;
            })
        });
        let [iterations, cg, factorizations, frames, shifted] = *counts.borrow();
        let per = |v: usize| v as f64 / frames.max(1) as f64;
        eprintln!(
            "{row}: per frame over {frames} frames: {:.2} Newton iterations, {:.1} CG iterations, {:.2} numeric factorisations ({:.2} of them shifted)",
            per(iterations),
            per(cg),
            per(factorizations),
            per(shifted)
        );
    }
    group.finish();
}

criterion_group!(benches, frames);
criterion_main!(benches);
