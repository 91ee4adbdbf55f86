//! The cloth ground truth across solver changes (issue "Ground truth at speed"): datasets
//! regenerated with today's solver must give the frames the solver gave before that work,
//! to within what its tolerance allows.
//!
//! The fixtures are the implicit-Euler frames of `cargo xtask evaluate --quick` at commit
//! 6df6769 (before the solver changes): `predictions/sim/<scene>/implicit-euler
//! .safetensors` with only its `positions` and `times` kept. They can be made again with
//! `git worktree add OLD 6df6769`, that command in OLD, and the same two tensors copied out.

use std::path::PathBuf;

use weft_sim::{ClothScene, ClothSimulation};

fn fixture(scene: &str) -> (Vec<f64>, Vec<usize>) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../fixtures/frames")
        .join(format!("{scene}-quick-6df6769.safetensors"));
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let t = st.tensor("positions").unwrap();
    assert_eq!(t.dtype(), safetensors::Dtype::F64);
    let values = t
        .data()
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
        .collect();
    (values, t.shape().to_vec())
}

/// Steps the quick built-in scene over the fixture's frames and checks, frame by frame:
/// - the old frame satisfies today's step equations: its residual force, given the old
///   frames before it, is within the solver's tolerance on every free DOF;
/// - today's frame is within `tolerance / (m_min / Δt²)` of the old one — the distance a
///   residual force of the tolerance moves the lightest vertex against its inertia alone
///   (springs and membranes only stiffen it further).
fn frames_agree_with_the_old_solver(scene: &str) {
    let (old, shape) = fixture(scene);
    let [frames, vertices, 3] = shape[..] else {
        panic!("{scene}: fixture shape {shape:?}")
    };
    let mut sim = ClothSimulation::new(ClothScene::builtin(scene, true).unwrap(), None).unwrap();
    assert_eq!(sim.mesh().num_vertices(), vertices, "{scene}: the quick mesh changed");
    let integrator = sim.integrator();
    let tolerance = integrator.settings.tolerance;
    let dt = integrator.dt();
    let m_min = integrator.masses().iter().copied().fold(f64::INFINITY, f64::min);
    let bound = tolerance / (m_min / (dt * dt));
    let fixed = integrator.fixed().to_vec();
    let x0 = integrator.positions().to_vec();
    let n = 3 * vertices;
    let old_frame = |f: usize| -> &[f64] {
        // Fixture frame f is the state after f + 1 steps; -1 is the start (at rest).
        if f == usize::MAX { &x0 } else { &old[f * n..(f + 1) * n] }
    };
    let mut grad = vec![0.0; n];
    let (mut worst_residual, mut worst_distance) = (0.0f64, 0.0f64);
    for f in 0..frames {
        sim.step().unwrap_or_else(|e| panic!("{scene} frame {}: {e}", f + 1));
        let prev1 = old_frame(f.wrapping_sub(1));
        let prev2 = if f == 0 { &x0[..] } else { old_frame(f.wrapping_sub(2)) };
        sim.integrator()
            .l_phys_gradient(prev2, prev1, old_frame(f), &mut grad)
            .unwrap();
        let residual = grad
            .iter()
            .zip(&fixed)
            .filter(|(_, fixed)| !**fixed)
            .fold(0.0f64, |m, (g, _)| m.max(g.abs()));
        let distance = sim
            .integrator()
            .positions()
            .iter()
            .zip(old_frame(f))
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(
            residual <= tolerance,
            "{scene} frame {}: the old frame's residual under today's equations is {residual:e} N, above the \
             tolerance {tolerance:e} N",
            f + 1
        );
        assert!(
            distance <= bound,
            "{scene} frame {}: today's frame is {distance:e} m from the old one, beyond {bound:e} m",
            f + 1
        );
        worst_residual = worst_residual.max(residual);
        worst_distance = worst_distance.max(distance);
    }
    eprintln!(
        "{scene}: {frames} frames; old frames' residual ≤ {worst_residual:.2e} N (tolerance {tolerance:.2e}), \
         today's frames within {worst_distance:.2e} m of them (bound {bound:.2e})"
    );
}

#[test]
fn quick_mass_spring_sheet_frames_match_the_solver_before_the_speed_work() {
    frames_agree_with_the_old_solver("sheet-ms");
}

#[test]
fn quick_fem_ball_frames_match_the_solver_before_the_speed_work() {
    frames_agree_with_the_old_solver("ball-fem");
}
