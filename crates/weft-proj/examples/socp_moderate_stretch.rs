//! The SOCP layer on an ordinary case: the paper-size sheet (`sheet(55, 1.0)`, 3025
//! vertices, 8856 edges, ε = 0.1) under a smooth stretch varying between 5 % and 30 % over
//! the sheet, with a smooth bump and a little deterministic noise. Prints the forward
//! pass's report (interior-point and polish iterations, seconds) and the same-run time of
//! Clarabel on the same problem.
//!
//! `cargo run --release -p weft-proj --example socp_moderate_stretch [SEED] [--verbose]`
//! (`--verbose`: the interior-point log of the default solver, with each iteration's
//! assembly and factorisation time, on standard error).

use std::time::Instant;

use weft_proj::{ConicSolver, InextensibilityLayer, SocpSettings};

const USAGE: &str = "socp_moderate_stretch [SEED] [--verbose]\n  SEED       draws the stretch field's phases and frequencies (default: a fixed field)\n  --verbose  the default solver's interior-point log on standard error";

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--help" || a == "-h") {
        println!("{USAGE}");
        return Ok(());
    }
    let verbose = args.iter().any(|a| a == "--verbose");
    // An optional seed draws the stretch field's phases and frequencies at random; any
    // other argument is an error, never read as a seed.
    let mut seed: Option<u64> = None;
    for a in args.iter().filter(|a| *a != "--verbose") {
        match (a.parse::<u64>(), seed) {
            (Ok(s), None) => seed = Some(s),
            (Ok(_), Some(_)) => return Err(format!("more than one seed given ({a})\nusage: {USAGE}").into()),
            (Err(_), _) => return Err(format!("unknown argument {a:?}\nusage: {USAGE}").into()),
        }
    }
    let rest = weft_mesh::generators::sheet(55, 1.0)?;
    let mut draw = {
        let mut state = seed.unwrap_or(0).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5;
        move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        }
    };
    let (fx, px, fy, py) = match seed {
        Some(_) => (
            1.0 + 4.0 * draw(),
            std::f64::consts::TAU * draw(),
            1.0 + 4.0 * draw(),
            std::f64::consts::TAU * draw(),
        ),
        None => (3.0, 1.0, 2.0, 0.5),
    };
    let mut state: u64 = 0x5EED;
    let mut noise = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.002
    };
    let pred: Vec<f64> = rest
        .positions()
        .iter()
        .flat_map(|p| {
            // Stretch factor between 1.05 and 1.30, smooth over the sheet.
            let s = 1.05 + 0.25 * (0.5 + 0.5 * (fx * p.x + px).sin() * (fy * p.y + py).cos());
            let z = 0.05 * (4.0 * p.x).sin() * (3.0 * p.y).cos();
            [s * p.x + noise(), s * p.y + noise(), z + noise()]
        })
        .collect();
    for (name, settings) in [
        (
            "default",
            SocpSettings {
                verbose,
                ..SocpSettings::default()
            },
        ),
        (
            "clarabel",
            SocpSettings {
                solver: ConicSolver::Clarabel,
                ..SocpSettings::default()
            },
        ),
    ] {
        let layer = InextensibilityLayer::new(&rest, 0.1, settings)?;
        let mut best = f64::INFINITY;
        let mut last = None;
        for _ in 0..3 {
            let t = Instant::now();
            let (_, report) = layer.forward(&pred)?;
            best = best.min(t.elapsed().as_secs_f64());
            last = Some(report);
        }
        println!(
            "{name}: best of 3 forward passes {:.3} s; {:?}",
            best,
            last.ok_or("no forward pass ran")?
        );
    }
    Ok(())
}
