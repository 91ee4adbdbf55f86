//! Consistent log-rotations across neighbours without an integer solver (docs/ACAP.md §A3).
//!
//! A rotation with principal log (ω, θ), θ ∈ [0, π], has the logs r = φ a with either
//! a = ω, φ = θ + 2πk or a = −ω, φ = 2π − θ + 2πk, k ∈ ℤ. Gao et al. choose the sign
//! s_i and the integer k_i per vertex by mixed-integer programs (Tan et al. §III-A:
//! "as-consistent-as-possible manner using mixed-integer programming"); weft replaces
//! them with the solver-free algorithm of docs/ACAP.md §A3:
//!
//! 1. propagation from a root per connected component, most reliable edge first;
//! 2. axis sweeps: flip s_i whenever Σ_j sign(a_i·a_j) < 0 over its 1-ring (edges at
//!    rotations within 0.02 rad of identity ignored) — each flip raises the objective;
//! 3. angle sweeps: k_i ← the exact integer minimiser of Σ_j (φ_i − φ_j)² — the energy
//!    never rises;
//! 4. a polish on the vector continuity energy Σ‖r_i − r_j‖² from three starts, keeping
//!    the lowest.

use nalgebra::Vector3;

use crate::rings::Rings;

/// A rotation closer than this to the identity has no meaningful axis: it takes its
/// parent's axis and φ = 2πk (docs/ACAP.md §A3, BFS rule).
const IDENTITY_ANGLE: f64 = 1e-6;
/// Edges at a rotation within this angle of the identity are ignored by the axis sweeps.
const AXIS_IGNORE_ANGLE: f64 = 0.02;
/// Upper bound on sweeps of each kind. Both sweeps terminate on their own (each change
/// strictly improves a bounded integer objective); this only guards pathological input.
const MAX_SWEEPS: usize = 10_000;

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// What the consistency pass did to one frame, with the energies before and after the
/// refinement sweeps (docs/ACAP.md §A3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConsistencyReport {
    /// Σ over 1-ring edges of sign(a_i·a_j) after the breadth-first pass (higher is better).
    pub bfs_axis_agreement: i64,
    /// The same after the axis sweeps.
    pub axis_agreement: i64,
    /// Σ over edges of (φ_i − φ_j)² after the breadth-first pass.
    pub bfs_angle_energy: f64,
    /// The same at the start of the angle sweeps (after any axis flips).
    pub pre_angle_sweep_energy: f64,
    /// The same after the angle sweeps.
    pub angle_energy: f64,
    /// Σ over edges of ‖r_i − r_j‖² of the log-rotations after the propagation.
    pub bfs_log_jump_energy: f64,
    /// Σ over edges of ‖r_i − r_j‖² of the final log-rotations.
    pub log_jump_energy: f64,
    /// Largest ‖r_i − r_j‖ over edges of the final log-rotations (radians).
    pub max_log_jump: f64,
    pub axis_flips: usize,
    pub angle_changes: usize,
}

#[derive(Debug, Clone, Copy)]
struct State {
    axis: Vector3<f64>,
    base: f64,
    k: i64,
}

impl State {
    fn phi(&self) -> f64 {
        self.base + TWO_PI * self.k as f64
    }
}

/// The representation (a, base, k) of the rotation with principal log (ω, θ) whose log
/// vector is closest to `target`.
fn closest_to(omega: Vector3<f64>, theta: f64, target: &Vector3<f64>) -> State {
    if theta < IDENTITY_ANGLE {
        let n = target.norm();
        let axis = if n > 0.0 { target / n } else { omega };
        return State {
            axis,
            base: 0.0,
            k: (n / TWO_PI).round() as i64,
        };
    }
    // Candidates (θ + 2πm) ω, m ∈ ℤ; the closest has θ + 2πm nearest to ω·target.
    let m = ((omega.dot(target) - theta) / TWO_PI).round() as i64;
    if theta + TWO_PI * m as f64 >= 0.0 {
        State {
            axis: omega,
            base: theta,
            k: m,
        }
    } else {
        // (θ + 2πm) ω = (2π − θ + 2π(−m − 1)) (−ω).
        State {
            axis: -omega,
            base: TWO_PI - theta,
            k: -m - 1,
        }
    }
}

/// Makes the principal logs `(axis, angle)` consistent over the 1-ring graph and returns
/// the log-rotation vectors r_i = φ_i a_i.
///
/// `roots` holds one vertex per connected component; `reference` (a previous frame's
/// log-rotations) seeds each root's sign and k so a sequence does not jump when the
/// root's rotation passes π (docs/ACAP.md §A3, step 4).
pub(crate) fn consistent_logs(
    principal: &[(Vector3<f64>, f64)],
    rings: &Rings,
    roots: &[usize],
    reference: Option<&[Vector3<f64>]>,
) -> (Vec<Vector3<f64>>, ConsistencyReport) {
    let n = principal.len();
    let near_identity: Vec<bool> = principal.iter().map(|&(_, t)| t < IDENTITY_ANGLE).collect();
    let mut is_root = vec![false; n];
    roots.iter().for_each(|&r| is_root[r] = true);

    let mut state = propagate(principal, rings, roots, reference, &near_identity);
    let bfs_state = state.clone();
    let ignored: Vec<bool> = principal.iter().map(|&(_, t)| t < AXIS_IGNORE_ANGLE).collect();
    let bfs_axis_agreement = axis_agreement(&state, &ignored, rings);
    let bfs_angle_energy = angle_energy(&state, rings);

    let axis_flips = axis_sweeps(&mut state, rings, &ignored, &is_root);
    let axis_agreement = axis_agreement(&state, &ignored, rings);
    let pre_angle_sweep_energy = angle_energy(&state, rings);

    let angle_changes = angle_sweeps(&mut state, rings, &is_root);
    let angle_energy = angle_energy(&state, rings);

    let bfs_logs = state_logs(&bfs_state, principal, &near_identity);
    let bfs_log_jump_energy = jump_energy(&bfs_logs, rings);
    let logs = best_polished(
        [state_logs(&state, principal, &near_identity), bfs_logs],
        principal,
        &near_identity,
        rings,
        roots,
        &is_root,
    );
    let (mut log_jump_energy, mut max_log_jump) = (0.0, 0.0f64);
    for i in 0..n {
        for &j in rings.neighbors(i) {
            if j > i {
                let d = (logs[i] - logs[j]).norm();
                log_jump_energy += d * d;
                max_log_jump = max_log_jump.max(d);
            }
        }
    }
    let report = ConsistencyReport {
        bfs_axis_agreement,
        axis_agreement,
        bfs_angle_energy,
        bfs_log_jump_energy,
        pre_angle_sweep_energy,
        angle_energy,
        log_jump_energy,
        max_log_jump,
        axis_flips,
        angle_changes,
    };
    (logs, report)
}

/// Step 1: propagation from each root (docs/ACAP.md §A3 step 1, with k by rounding). The
/// release visits vertices breadth-first; weft visits them most-reliable-edge first
/// (Prim's order on min(θ_i, θ_j)), so a region of large rotations is traversed through
/// its own edges rather than through near-identity vertices whose axes are noise. Without
/// this, a sheet folded by π split into two domains with r = ±π a (a 2π seam) that no
/// local sweep can merge.
fn propagate(
    principal: &[(Vector3<f64>, f64)],
    rings: &Rings,
    roots: &[usize],
    reference: Option<&[Vector3<f64>]>,
    near_identity: &[bool],
) -> Vec<State> {
    let n = principal.len();
    let mut state: Vec<State> = principal
        .iter()
        .map(|&(a, t)| State { axis: a, base: t, k: 0 })
        .collect();
    let mut visited = vec![false; n];
    let mut heap = std::collections::BinaryHeap::new();
    for &root in roots {
        let (omega, theta) = principal[root];
        state[root] = match reference {
            Some(r) => closest_to(omega, theta, &r[root]),
            None => State {
                axis: omega,
                base: theta,
                k: 0,
            },
        };
        visited[root] = true;
        push_edges(&mut heap, root, principal, rings, &visited);
        while let Some(Frontier {
            parent: i, child: j, ..
        }) = heap.pop()
        {
            if visited[j] {
                continue;
            }
            visited[j] = true;
            let parent = state[i];
            let (omega, theta) = principal[j];
            let (axis, base) = if near_identity[j] {
                (parent.axis, 0.0)
            } else if omega.dot(&parent.axis) < 0.0 {
                (-omega, TWO_PI - theta)
            } else {
                (omega, theta)
            };
            let k = ((parent.phi() - base) / TWO_PI).round() as i64;
            state[j] = State { axis, base, k };
            push_edges(&mut heap, j, principal, rings, &visited);
        }
    }
    state
}

/// The exact integer minimiser k of Σ_j (base + 2πk − φ_j)² over vertex `i`'s neighbours.
fn best_k(state: &[State], rings: &Rings, i: usize, base: f64) -> i64 {
    let nb = rings.neighbors(i);
    let mean = nb.iter().map(|&j| state[j].phi()).sum::<f64>() / nb.len().max(1) as f64;
    ((mean - base) / TWO_PI).round() as i64
}

/// Step 2: axis sweeps — flip a vertex's axis whenever most of its (non-ignored) 1-ring
/// disagrees with it, taking the best k for the flipped base. Returns the flips made.
fn axis_sweeps(state: &mut [State], rings: &Rings, ignored: &[bool], is_root: &[bool]) -> usize {
    let mut flips = 0;
    for _ in 0..MAX_SWEEPS {
        let mut flipped = false;
        for i in 0..state.len() {
            if is_root[i] || ignored[i] {
                continue;
            }
            let local: i64 = rings
                .neighbors(i)
                .iter()
                .filter(|&&j| !ignored[j])
                .map(|&j| sign(state[i].axis.dot(&state[j].axis)))
                .sum();
            if local < 0 {
                let base = TWO_PI - state[i].base;
                let k = best_k(state, rings, i, base);
                state[i] = State {
                    axis: -state[i].axis,
                    base,
                    k,
                };
                flips += 1;
                flipped = true;
            }
        }
        if !flipped {
            break;
        }
    }
    flips
}

/// Step 3: angle sweeps — coordinate descent on k with the roots fixed, accepting strict
/// decreases of Σ_j (φ_i − φ_j)² only so ties cannot cycle. Returns the changes made.
fn angle_sweeps(state: &mut [State], rings: &Rings, is_root: &[bool]) -> usize {
    let local_energy = |state: &[State], i: usize, base: f64, k: i64| -> f64 {
        let phi = base + TWO_PI * k as f64;
        rings.neighbors(i).iter().map(|&j| (phi - state[j].phi()).powi(2)).sum()
    };
    let mut changes = 0;
    for _ in 0..MAX_SWEEPS {
        let mut changed = false;
        for i in 0..state.len() {
            if is_root[i] {
                continue;
            }
            let s = state[i];
            let k = best_k(state, rings, i, s.base);
            if k != s.k {
                let (old, new) = (local_energy(state, i, s.base, s.k), local_energy(state, i, s.base, k));
                if new < old * (1.0 - 1e-12) {
                    state[i].k = k;
                    changes += 1;
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
    }
    changes
}

/// Step 4: the final vectors, polished on the true continuity energy Σ‖r_i − r_j‖² (each
/// vertex takes its best representative given its neighbours). The scalar energy of
/// step 3 cannot see two neighbours with r = +π a and −π a, which are the same rotation.
/// Three starts are polished and the lowest energy kept: the given ones (the refined and
/// the propagated state) and the principal logs (θ ≤ π everywhere) with the roots as
/// seeded. On rough fields with neighbours over 2π/3 apart the propagation can commit a
/// whole region to the wrong turn, which single-vertex moves cannot undo, while the
/// principal logs are already close to the optimum there (docs/ACAP.md §A3).
fn best_polished(
    starts: [Vec<Vector3<f64>>; 2],
    principal: &[(Vector3<f64>, f64)],
    near_identity: &[bool],
    rings: &Rings,
    roots: &[usize],
    is_root: &[bool],
) -> Vec<Vector3<f64>> {
    let mut principal_logs: Vec<Vector3<f64>> = principal.iter().map(|&(o, t)| o * t).collect();
    for &root in roots {
        principal_logs[root] = starts[0][root];
    }
    let [refined, propagated] = starts;
    [refined, propagated, principal_logs]
        .into_iter()
        .map(|start| polish(start, principal, near_identity, rings, is_root))
        .min_by(|a, b| jump_energy(a, rings).total_cmp(&jump_energy(b, rings)))
        .expect("three candidates")
}

fn sign(x: f64) -> i64 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}

fn axis_agreement(state: &[State], ignored: &[bool], rings: &Rings) -> i64 {
    let mut total = 0;
    for i in 0..state.len() {
        for &j in rings.neighbors(i) {
            if j > i && !ignored[i] && !ignored[j] {
                total += sign(state[i].axis.dot(&state[j].axis));
            }
        }
    }
    total
}

fn angle_energy(state: &[State], rings: &Rings) -> f64 {
    let mut total = 0.0;
    for i in 0..state.len() {
        for &j in rings.neighbors(i) {
            if j > i {
                total += (state[i].phi() - state[j].phi()).powi(2);
            }
        }
    }
    total
}

/// A frontier edge of the propagation, ordered by reliability min(θ_parent, θ_child).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Frontier {
    reliability: f64,
    parent: usize,
    child: usize,
}

impl Eq for Frontier {}

impl PartialOrd for Frontier {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Frontier {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        // Highest reliability first; ties broken by lowest child index for determinism.
        self.reliability
            .total_cmp(&other.reliability)
            .then_with(|| other.child.cmp(&self.child))
            .then_with(|| other.parent.cmp(&self.parent))
    }
}

fn push_edges(
    heap: &mut std::collections::BinaryHeap<Frontier>,
    i: usize,
    principal: &[(Vector3<f64>, f64)],
    rings: &Rings,
    visited: &[bool],
) {
    for &j in rings.neighbors(i) {
        if !visited[j] {
            heap.push(Frontier {
                reliability: principal[i].1.min(principal[j].1),
                parent: i,
                child: j,
            });
        }
    }
}

/// Log vectors of a state; a near-identity rotation keeps its exact principal log when
/// k = 0 and is 2πk along its (inherited) axis otherwise.
fn state_logs(state: &[State], principal: &[(Vector3<f64>, f64)], near_identity: &[bool]) -> Vec<Vector3<f64>> {
    state
        .iter()
        .zip(principal)
        .zip(near_identity)
        .map(|((s, &(omega, theta)), &near)| {
            if near && s.k == 0 {
                omega * theta
            } else {
                s.axis * s.phi()
            }
        })
        .collect()
}

/// Coordinate descent on Σ_edges ‖r_i − r_j‖² over each vertex's representatives
/// (θ_i + 2πm) ω_i, m ∈ ℤ (or 2πm u, any unit u, near the identity); roots fixed.
fn polish(
    mut logs: Vec<Vector3<f64>>,
    principal: &[(Vector3<f64>, f64)],
    near_identity: &[bool],
    rings: &Rings,
    is_root: &[bool],
) -> Vec<Vector3<f64>> {
    let local = |logs: &[Vector3<f64>], i: usize, r: &Vector3<f64>| -> f64 {
        rings.neighbors(i).iter().map(|&j| (r - logs[j]).norm_squared()).sum()
    };
    for _ in 0..MAX_SWEEPS {
        let mut changed = false;
        for i in 0..logs.len() {
            let nb = rings.neighbors(i);
            if is_root[i] || nb.is_empty() {
                continue;
            }
            let mean: Vector3<f64> = nb.iter().map(|&j| logs[j]).sum::<Vector3<f64>>() / nb.len() as f64;
            let (omega, theta) = principal[i];
            let candidate = if near_identity[i] {
                let m = (mean.norm() / TWO_PI).round();
                if m == 0.0 {
                    omega * theta
                } else {
                    mean.normalize() * (TWO_PI * m)
                }
            } else {
                let m = ((omega.dot(&mean) - theta) / TWO_PI).round();
                omega * (theta + TWO_PI * m)
            };
            let (old, new) = (local(&logs, i, &logs[i]), local(&logs, i, &candidate));
            if new < old * (1.0 - 1e-12) {
                logs[i] = candidate;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    logs
}

fn jump_energy(logs: &[Vector3<f64>], rings: &Rings) -> f64 {
    let mut total = 0.0;
    for i in 0..logs.len() {
        for &j in rings.neighbors(i) {
            if j > i {
                total += (logs[i] - logs[j]).norm_squared();
            }
        }
    }
    total
}
