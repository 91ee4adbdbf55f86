//! The guarded roll-out's figures on a cloth scene (docs/GUARD.md, "Measured"): the
//! ground truth first, then on every frame, from the truth's history,
//!
//! - the inertial predictor's one-step error (mm, M_rms of the frame) and its estimate;
//! - Newton iterations to the truth's tolerance from the solver's own start (the inertial
//!   prediction) and from the truth plus seeded noise of 0.1, 1 and 5 mm RMS — what a
//!   surrogate of that one-step error would save;
//! - whether the estimate's condition was certified, and its ratio to the true error;
//!
//! then guarded roll-outs of the inertial predictor at several tolerances τ: frames
//! accepted, Newton iterations and the M_rms against the truth.
//!
//! ```sh
//! cargo run --release -p weft-sim --example guard_sheet -- [--scene sheet-ms] [--full] \
//!     [--frames N] [--preconditioner jacobi|lagged-cholesky] [--projection never|when-indefinite|always]
//! ```
//! Defaults: the quick `sheet-ms` (9 × 9, 30 frames); `--full` the standard-size scene
//! (slow; one-step figures only, and no dense eigen-decomposition for the exact modulus),
//! `--frames N` its first N frames; the estimate's CG preconditioner is the guard's
//! default (the lagged Cholesky factor); `--projection` the Hessian projection of the
//! one-step figures' Newton solves (default: the ground truth's).

use std::sync::Arc;

use weft_linalg::{SymmetricMatrix, SymmetricPattern};
use weft_sim::ImplicitEuler;
use weft_sim::energy::{Energy, checked_pairs};
use weft_sim::guard::{Acceptance, Correction, EstimatePreconditioner, Guard, GuardSettings, InertialPredictor};
use weft_sim::newton::HessianProjection;
use weft_sim::rng::SplitMix64;
use weft_sim::{ClothScene, ClothSimulation};

fn m_rms_mm(a: &[f64], b: &[f64]) -> f64 {
    let sq: f64 = a.iter().zip(b).map(|(a, b)| (a - b).powi(2)).sum();
    1e3 * (sq / a.len() as f64).sqrt()
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// `truth` with seeded noise of `mm` RMS per coordinate on the free DOFs.
fn noisy(truth: &[f64], fixed: &[bool], mm: f64, rng: &mut SplitMix64) -> Vec<f64> {
    // Uniform on ±a has RMS a/√3.
    let a = 1e-3 * mm * 3f64.sqrt();
    truth
        .iter()
        .zip(fixed)
        .map(|(x, f)| if *f { *x } else { x + a * (2.0 * rng.unit() - 1.0) })
        .collect()
}

/// The exact modulus of the step at `x`: the smallest eigenvalue of
/// `M^{−½}(M/Δt² + H)M^{−½}` on the free DOFs (1/s²), by a dense eigen-decomposition —
/// what the guard's cheap certificate bounds from below.
fn exact_modulus(integrator: &ImplicitEuler, x: &[f64]) -> Result<f64, Box<dyn std::error::Error>> {
    let n = x.len();
    let terms: Vec<&dyn Energy> = integrator.terms().iter().map(|t| t.as_ref()).collect();
    let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(n / 3, checked_pairs(n, &terms)?));
    let mut h = SymmetricMatrix::zeros(pattern);
    for t in &terms {
        t.add_hessian(x, false, &mut h);
    }
    let free: Vec<usize> = (0..n).filter(|&i| !integrator.fixed()[i]).collect();
    let m = |i: usize| integrator.masses()[i / 3];
    let a = nalgebra::DMatrix::from_fn(free.len(), free.len(), |r, c| {
        let (i, j) = (free[r], free[c]);
        h.get(i, j) / (m(i) * m(j)).sqrt() + if i == j { 1.0 / integrator.dt().powi(2) } else { 0.0 }
    });
    Ok(a.symmetric_eigen().eigenvalues.min())
}

fn one_step_figures(
    scene: &ClothScene,
    truth: &[Vec<f64>],
    preconditioner: EstimatePreconditioner,
    projection: Option<HessianProjection>,
) -> Result<(), Box<dyn std::error::Error>> {
    let mut sim = ClothSimulation::new(scene.clone(), None)?;
    let predictor = InertialPredictor::for_integrator(sim.integrator());
    let settings = GuardSettings {
        preconditioner,
        ..GuardSettings::ground_truth()
    };
    let mut guard = Guard::new(sim.integrator(), &scene.name, Box::new(predictor), settings)?;
    // The noisy proposals get a guard of their own, so that the inertial proposals' lagged
    // factor follows one trajectory, as in a guarded roll-out.
    let predictor = InertialPredictor::for_integrator(sim.integrator());
    let mut noisy_guard = Guard::new(sim.integrator(), &scene.name, Box::new(predictor), settings)?;
    // Wall time and factorisations of the inertial proposals' estimates.
    let (mut estimate_seconds, mut estimates, mut factorizations) = (0.0, 0usize, 0usize);
    let noise = [0.1, 1.0, 5.0];
    let (mut err, mut est, mut own, mut certified) = (Vec::new(), Vec::new(), Vec::new(), 0usize);
    let (mut ratio, mut bound_ratio, mut indefinite, mut cg) = (Vec::new(), Vec::new(), 0usize, Vec::new());
    let mut from_noisy = vec![Vec::new(); noise.len()];
    let mut ratio_noisy = vec![Vec::new(); noise.len()];
    // How far from the truth's frame each solve from a noisy start landed (mm).
    let mut landed = vec![Vec::new(); noise.len()];
    let mut rng = SplitMix64::new(73);
    let (mut modulus, mut certified_modulus) = (Vec::new(), Vec::new());
    for m in 1..truth.len() {
        let prev = if m >= 2 { &truth[m - 2] } else { &truth[0] };
        sim.integrator_mut().set_state(&truth[m - 1], prev)?;
        let prescribed = sim.prescribed_at(m);
        let integrator = sim.integrator_mut();
        let mut x = integrator.inertial_start(&prescribed)?;
        let clock = std::time::Instant::now();
        let e = guard.estimate(integrator, &x)?;
        estimate_seconds += clock.elapsed().as_secs_f64();
        (estimates, factorizations) = (estimates + 1, factorizations + e.factorizations);
        err.push(m_rms_mm(&x, &truth[m]));
        est.push(e.mm);
        certified += usize::from(e.certified);
        indefinite += usize::from(e.projected);
        cg.push(e.cg_iterations as f64);
        let d = guard.mass_norm(&x, &truth[m]);
        ratio.push(e.distance / d);
        if e.certified {
            bound_ratio.push(e.residual_m_inv / e.modulus / d);
        }
        let inv_dt2 = 1.0 / integrator.dt().powi(2);
        // A dense eigen-decomposition is for the small meshes only.
        if x.len() < 2000 {
            modulus.push(exact_modulus(integrator, &x)? / inv_dt2);
        }
        certified_modulus.push(e.modulus / inv_dt2);
        let mut settings = integrator.settings;
        if let Some(p) = projection {
            settings.projection = p;
        }
        own.push(integrator.solve_step_from(&prescribed, &mut x, &settings)?.iterations as f64);
        for (k, &mm) in noise.iter().enumerate() {
            let mut x = noisy(&truth[m], integrator.fixed(), mm, &mut rng);
            let e = noisy_guard.estimate(integrator, &x)?;
            let truth_distance = guard.mass_norm(&x, &truth[m]);
            ratio_noisy[k].push(e.distance / truth_distance);
            from_noisy[k].push(integrator.solve_step_from(&prescribed, &mut x, &settings)?.iterations as f64);
            landed[k].push(m_rms_mm(&x, &truth[m]));
        }
    }
    let frames = truth.len() - 1;
    println!(
        "{}: {frames} frames, one step from the truth's history; preconditioner {preconditioner:?}: {:.1} ms per estimate of an inertial proposal, {factorizations} factorisations in {estimates}",
        scene.name,
        1e3 * estimate_seconds / estimates.max(1) as f64
    );
    println!(
        "  inertial predictor: one-step error {:.3} mm mean (max {:.3}), estimate {:.3} mm mean; certified on {certified}/{frames}",
        mean(&err),
        err.iter().fold(0.0f64, |a, b| a.max(*b)),
        mean(&est)
    );
    println!(
        "  Newton-step estimate / true distance: {:.3} mean (min {:.3}, max {:.3}); exact Hessian indefinite on {indefinite}/{frames}; {:.1} CG iterations; certified bound / true distance {:.1} mean",
        mean(&ratio),
        ratio.iter().fold(f64::INFINITY, |a, b| a.min(*b)),
        ratio.iter().fold(0.0f64, |a, b| a.max(*b)),
        mean(&cg),
        mean(&bound_ratio)
    );
    if !modulus.is_empty() {
        println!(
            "  modulus at the inertial proposal / (1/Δt²): exact {:.3} mean (min {:.3}), certified bound {:.3} mean (min {:.3})",
            mean(&modulus),
            modulus.iter().fold(f64::INFINITY, |a, b| a.min(*b)),
            mean(&certified_modulus),
            certified_modulus.iter().fold(f64::INFINITY, |a, b| a.min(*b))
        );
    }
    println!(
        "  Newton iterations to the truth's tolerance: {:.2} from the solver's own start",
        mean(&own)
    );
    for (k, mm) in noise.iter().enumerate() {
        println!(
            "    from the truth + {mm} mm noise: {:.2} iterations, landing {:.4} mm from the truth's frame; estimate / true distance {:.2} mean (min {:.2})",
            mean(&from_noisy[k]),
            mean(&landed[k]),
            mean(&ratio_noisy[k]),
            ratio_noisy[k].iter().fold(f64::INFINITY, |a, b| a.min(*b))
        );
    }
    Ok(())
}

fn guarded_runs(
    scene: &ClothScene,
    truth: &[Vec<f64>],
    truth_iterations: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    println!("  ground truth: {truth_iterations} Newton iterations over the run");
    let mut rows: Vec<(String, GuardSettings)> = vec![("truth's tolerance".into(), GuardSettings::ground_truth())];
    for tau in [0.1, 0.5, 1.0, 2.0, 5.0, 1e9] {
        let mut s = GuardSettings::millimetres(tau)?;
        s.correction = Correction::ToTolerance;
        rows.push((format!("τ = {tau} mm"), s));
        let mut u = s;
        u.acceptance = Acceptance::CertifiedBound;
        rows.push((format!("τ = {tau} mm, certified bound"), u));
    }
    for (label, settings) in rows {
        let mut sim = ClothSimulation::new(scene.clone(), None)?;
        let predictor = InertialPredictor::for_integrator(sim.integrator());
        let mut guard = Guard::new(sim.integrator(), &scene.name, Box::new(predictor), settings)?;
        let (mut sq, mut worst) = (0.0, 0.0f64);
        for reference in &truth[1..] {
            let f = sim.step_guarded(&mut guard, Some(reference))?;
            let e = f.report.error.expect("a reference was given");
            sq += e.m_rms_mm.powi(2);
            worst = worst.max(e.m_rms_mm);
        }
        let t = guard.totals();
        println!(
            "  {label:>34}: accepted {:>3}/{} (no certified bound {}), Newton iterations {:>4}, M_rms {:.3} mm (worst frame {:.3})",
            t.accepted,
            t.frames,
            t.unverified,
            t.newton_iterations,
            (sq / t.frames as f64).sqrt(),
            worst
        );
    }
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let name = args
        .iter()
        .position(|a| a == "--scene")
        .and_then(|i| args.get(i + 1))
        .map_or("sheet-ms", String::as_str);
    let quick = !args.iter().any(|a| a == "--full");
    let mut scene = ClothScene::builtin(name, quick)?;
    if let Some(f) = args.iter().position(|a| a == "--frames").and_then(|i| args.get(i + 1)) {
        scene.frames = f.parse()?;
    }
    let preconditioner = match args
        .iter()
        .position(|a| a == "--preconditioner")
        .and_then(|i| args.get(i + 1))
    {
        None => EstimatePreconditioner::default(),
        Some(p) if p == "jacobi" => EstimatePreconditioner::Jacobi,
        Some(p) if p == "lagged-cholesky" => EstimatePreconditioner::LaggedCholesky,
        Some(p) => return Err(format!("--preconditioner {p}: expected jacobi or lagged-cholesky").into()),
    };
    let mut sim = ClothSimulation::new(scene.clone(), None)?;
    let mut truth = vec![sim.integrator().positions().to_vec()];
    let mut iterations = 0;
    let clock = std::time::Instant::now();
    for _ in 0..scene.frames {
        let f = sim.step()?;
        iterations += f.report.newton.iterations;
        truth.push(f.positions);
    }
    println!(
        "ground truth: {:.1} ms per frame, {:.2} Newton iterations per frame",
        1e3 * clock.elapsed().as_secs_f64() / scene.frames.max(1) as f64,
        iterations as f64 / scene.frames.max(1) as f64
    );
    // The Newton solves of the one-step figures with another Hessian projection than
    // the ground truth's (which made the truth's frames).
    let projection = match args
        .iter()
        .position(|a| a == "--projection")
        .and_then(|i| args.get(i + 1))
    {
        None => None,
        Some(p) if p == "never" => Some(HessianProjection::Never),
        Some(p) if p == "when-indefinite" => Some(HessianProjection::WhenIndefinite),
        Some(p) if p == "always" => Some(HessianProjection::Always),
        Some(p) => return Err(format!("--projection {p}: expected never, when-indefinite or always").into()),
    };
    one_step_figures(&scene, &truth, preconditioner, projection)?;
    if !quick {
        return Ok(());
    }
    guarded_runs(&scene, &truth, iterations)
}
