use super::*;
use std::sync::Arc;
use weft_testkit::TestRng;

/// A random SPD matrix on a random sparse pattern: B + Bᵀ made diagonally dominant.
fn random_spd(n: usize, rng: &mut TestRng) -> SymmetricMatrix {
    let pairs: Vec<(usize, usize)> = (0..3 * n)
        .map(|_| {
            (
                (rng.uniform(0.0, n as f64)) as usize,
                (rng.uniform(0.0, n as f64)) as usize,
            )
        })
        .collect();
    let pattern = Arc::new(SymmetricPattern::new(n, pairs.iter().copied()));
    let mut a = SymmetricMatrix::zeros(pattern);
    let mut rowsum = vec![0.0; n];
    for &(r, c) in &pairs {
        if r != c {
            let v = rng.uniform(-1.0, 1.0);
            a.add(r.min(c), r.max(c), v);
            rowsum[r] += v.abs();
            rowsum[c] += v.abs();
        }
    }
    for i in 0..n {
        a.add(i, i, rowsum[i] + 0.5);
    }
    a
}

#[test]
fn cholesky_solves_random_spd_systems_to_machine_precision() {
    let mut rng = TestRng::new(1);
    let a = random_spd(200, &mut rng);
    let solver = CholeskySolver::new(a.pattern().clone()).unwrap();
    let f = solver.factorize(&a).unwrap();
    let b = rng.vec(200, -1.0, 1.0);
    let mut x = b.clone();
    f.solve_in_place(&mut x);
    let mut r = vec![0.0; 200];
    a.mul_vec(&x, &mut r);
    let err = r.iter().zip(&b).map(|(r, b)| (r - b).abs()).fold(0.0, f64::max);
    assert!(err < 1e-12, "residual {err}");
}

#[test]
fn cholesky_reuses_symbolic_factorisation_for_new_values() {
    let mut rng = TestRng::new(2);
    let a = random_spd(50, &mut rng);
    let solver = CholeskySolver::new(a.pattern().clone()).unwrap();
    let mut a2 = a.clone();
    a2.add_diagonal(10.0);
    for m in [&a, &a2] {
        let mut x = vec![1.0; 50];
        solver.factorize(m).unwrap().solve_in_place(&mut x);
        let mut r = vec![0.0; 50];
        m.mul_vec(&x, &mut r);
        assert!(r.iter().all(|v| (v - 1.0).abs() < 1e-12));
    }
}

#[test]
fn cholesky_rejects_indefinite_and_nan_matrices() {
    let pattern = Arc::new(SymmetricPattern::new(2, [(0, 1)]));
    let mut a = SymmetricMatrix::zeros(pattern.clone());
    a.add(0, 0, 1.0);
    a.add(1, 1, 1.0);
    a.add(0, 1, 2.0);
    let solver = CholeskySolver::new(pattern).unwrap();
    assert!(matches!(solver.factorize(&a), Err(Error::NotPositiveDefinite)));
    a.add(0, 0, f64::NAN);
    assert!(matches!(solver.factorize(&a), Err(Error::NonFinite(_))));
}

#[test]
fn pattern_slots_are_symmetric_and_include_the_diagonal() {
    let p = SymmetricPattern::from_vertex_pairs(3, [(0, 2)]);
    assert_eq!(p.dim(), 9);
    assert_eq!(p.slot(1, 7), p.slot(7, 1));
    assert!(p.slot(1, 7).is_some());
    assert!(p.slot(0, 4).is_none(), "vertices 0 and 1 are not coupled");
    assert!((0..9).all(|i| p.slot(i, i).is_some()));
}

#[test]
fn vertex_block_assembly_matches_entrywise_assembly() {
    let mut rng = TestRng::new(8);
    let pairs = [(0, 1), (1, 3), (2, 3), (0, 3)];
    let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(4, pairs));
    let mut by_block = SymmetricMatrix::zeros(pattern.clone());
    let mut by_entry = SymmetricMatrix::zeros(pattern);
    for &(u, v) in pairs.iter().chain(&[(2, 2), (3, 3)]) {
        let block = [0; 3].map(|_| [0; 3].map(|_| rng.uniform(-1.0, 1.0)));
        // Off-diagonal pairs given in both orders: the lower one must be ignored.
        by_block.add_vertex_block(u, v, &block);
        if u != v {
            by_block.add_vertex_block(v, u, &block);
        }
        for i in 0..3 {
            for j in 0..3 {
                by_entry.add(3 * u + i, 3 * v + j, block[i][j]);
            }
        }
    }
    assert_eq!(by_block.values(), by_entry.values());
}

#[test]
fn vertex_block_product_matches_the_dense_product() {
    // Random values on every stored entry of a vertex-block pattern (pairs given in both
    // orders, one isolated vertex): the block-by-block product must equal the dense
    // symmetric matrix's, and diagonal_block must read both triangles.
    let mut rng = TestRng::new(10);
    let nv = 7;
    let pairs = [(0, 1), (3, 1), (2, 3), (0, 3), (6, 2), (4, 6), (1, 6)];
    let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(nv, pairs));
    let mut a = SymmetricMatrix::zeros(pattern.clone());
    a.values_mut().iter_mut().for_each(|v| *v = rng.uniform(-1.0, 1.0));
    let n = 3 * nv;
    let dense: Vec<Vec<f64>> = (0..n).map(|r| (0..n).map(|c| a.get(r, c)).collect()).collect();
    let x = rng.vec(n, -1.0, 1.0);
    let mut y = vec![f64::NAN; n];
    a.mul_vec(&x, &mut y);
    for r in 0..n {
        let expected: f64 = (0..n).map(|c| dense[r][c] * x[c]).sum();
        assert!((y[r] - expected).abs() < 1e-14, "row {r}: {} against {expected}", y[r]);
    }
    for v in 0..nv {
        let d = a.diagonal_block(v).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                assert_eq!(d[i][j], dense[3 * v + i][3 * v + j]);
            }
        }
    }
    // add_matrix adds slot by slot on the same structure (another Arc of an equal
    // pattern too) and refuses another pattern.
    let mut twice = SymmetricMatrix::zeros(Arc::new(SymmetricPattern::from_vertex_pairs(nv, pairs)));
    twice.add_matrix(&a).unwrap();
    twice.add_matrix(&a).unwrap();
    assert!(twice.values().iter().zip(a.values()).all(|(t, v)| *t == 2.0 * v));
    let other = SymmetricMatrix::zeros(Arc::new(SymmetricPattern::from_vertex_pairs(nv, [(0, 1)])));
    assert!(matches!(twice.add_matrix(&other), Err(Error::PatternMismatch)));
    // A scalar pattern has no vertex blocks.
    let scalar = SymmetricMatrix::zeros(Arc::new(SymmetricPattern::new(3, [(0, 1)])));
    assert!(scalar.diagonal_block(0).is_none());
}

#[test]
fn vertex_block_ordering_solves_block_systems() {
    // A chain of 40 vertices with random SPD 3 × 3 couplings, ordered on the vertex graph.
    let mut rng = TestRng::new(9);
    let nv = 40;
    let pairs: Vec<(usize, usize)> = (0..nv - 1).map(|v| (v, v + 1)).chain([(0, nv - 1), (5, 30)]).collect();
    let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(nv, pairs.iter().copied()));
    let mut a = SymmetricMatrix::zeros(pattern.clone());
    for &(u, v) in &pairs {
        let w = rng.uniform(0.1, 1.0);
        // A spring-like PSD block w [[I, −I], [−I, I]].
        for k in 0..3 {
            a.add(3 * u + k, 3 * u + k, w);
            a.add(3 * v + k, 3 * v + k, w);
            a.add(3 * u.min(v) + k, 3 * u.max(v) + k, -w);
        }
    }
    a.add_diagonal(0.05);
    let solver = CholeskySolver::new(pattern).unwrap();
    assert!(solver.factor_nnz() > 0);
    let b = rng.vec(3 * nv, -1.0, 1.0);
    let mut x = b.clone();
    solver.factorize(&a).unwrap().solve_in_place(&mut x);
    let mut r = vec![0.0; 3 * nv];
    a.mul_vec(&x, &mut r);
    let err = r.iter().zip(&b).map(|(r, b)| (r - b).abs()).fold(0.0, f64::max);
    assert!(err < 1e-12, "residual {err}");
}

/// A random SPD matrix of dense `3 × 3` blocks on an `nx × ny × nz` vertex grid with the
/// 26-neighbour stencil (a tet mesh's vertex graph is a subset of it).
fn grid_block_spd(nx: usize, ny: usize, nz: usize, rng: &mut TestRng) -> SymmetricMatrix {
    let id = |i: usize, j: usize, k: usize| (k * ny + j) * nx + i;
    let mut pairs = Vec::new();
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                for (di, dj, dk) in [
                    (1, 0, 0),
                    (0, 1, 0),
                    (0, 0, 1),
                    (1, 1, 0),
                    (1, 0, 1),
                    (0, 1, 1),
                    (1, 1, 1),
                ] {
                    if i + di < nx && j + dj < ny && k + dk < nz {
                        pairs.push((id(i, j, k), id(i + di, j + dj, k + dk)));
                    }
                }
            }
        }
    }
    let nv = nx * ny * nz;
    let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(nv, pairs.iter().copied()));
    let mut a = SymmetricMatrix::zeros(pattern);
    for &(u, v) in &pairs {
        // w [[G, −G], [−G, G]] with G = ggᵀ + 0.1 I: PSD and anisotropic.
        let g = [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)];
        let block = [0, 1, 2].map(|r| [0, 1, 2].map(|c| g[r] * g[c] + if r == c { 0.1 } else { 0.0 }));
        let neg = block.map(|row| row.map(|x| -x));
        a.add_vertex_block(u, u, &block);
        a.add_vertex_block(v, v, &block);
        a.add_vertex_block(u.min(v), u.max(v), &neg);
    }
    a.add_diagonal(1e-3);
    a
}

fn max_residual(a: &SymmetricMatrix, x: &[f64], b: &[f64]) -> f64 {
    let mut r = vec![0.0; b.len()];
    a.mul_vec(x, &mut r);
    r.iter().zip(b).map(|(r, b)| (r - b).abs()).fold(0.0, f64::max)
}

#[test]
fn two_domain_factorisation_matches_the_sequential_one() {
    let mut rng = TestRng::new(10);
    let a = grid_block_spd(4, 5, 30, &mut rng);
    let n = a.dim();
    let split = CholeskySolver::with_substructuring(a.pattern().clone(), Substructuring::Always).unwrap();
    let whole = CholeskySolver::with_substructuring(a.pattern().clone(), Substructuring::Never).unwrap();
    assert_eq!(
        split.domains(),
        2,
        "an elongated grid has a balanced level-set separator"
    );
    assert_eq!(whole.domains(), 1);
    // Three right-hand sides at once; the split solve must agree with the sequential one
    // to round-off and leave a residual at machine precision.
    let b = rng.vec(3 * n, -1.0, 1.0);
    let (mut xs, mut xw) = (b.clone(), b.clone());
    split.factorize(&a).unwrap().solve_many_in_place(&mut xs, 3);
    whole.factorize(&a).unwrap().solve_many_in_place(&mut xw, 3);
    for c in 0..3 {
        let range = c * n..(c + 1) * n;
        let res = max_residual(&a, &xs[range.clone()], &b[range.clone()]);
        assert!(res < 1e-10, "split residual {res}");
        let diff = xs[range.clone()]
            .iter()
            .zip(&xw[range])
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
        let scale = xw.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(diff < 1e-9 * scale, "split and sequential solutions differ by {diff}");
    }
}

#[test]
fn two_domain_split_handles_disconnected_and_fixed_vertices() {
    // Two grids side by side (no coupling) and Dirichlet rows from `constrain_dofs`.
    let mut rng = TestRng::new(11);
    let g = grid_block_spd(3, 3, 24, &mut rng);
    let nv = g.dim() / 3;
    let pairs: Vec<(usize, usize)> = g
        .pattern()
        .entries()
        .filter(|&(_, r, c)| r % 3 == 0 && c % 3 == 0 && r != c)
        .flat_map(|(_, r, c)| [(r / 3, c / 3), (r / 3 + nv, c / 3 + nv)])
        .collect();
    let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(2 * nv, pairs));
    let mut a = SymmetricMatrix::zeros(pattern.clone());
    for copy in 0..2 {
        for (slot, r, c) in g.pattern().entries() {
            a.add(
                r + 3 * nv * copy,
                c + 3 * nv * copy,
                g.values()[slot] * (1.0 + copy as f64),
            );
        }
    }
    let fixed: Vec<bool> = (0..a.dim()).map(|i| i % 7 == 0).collect();
    a.constrain_dofs(&fixed);
    let solver = CholeskySolver::with_substructuring(pattern, Substructuring::Always).unwrap();
    assert_eq!(solver.domains(), 2);
    let b = rng.vec(a.dim(), -1.0, 1.0);
    let mut x = b.clone();
    solver.factorize(&a).unwrap().solve_in_place(&mut x);
    assert!(max_residual(&a, &x, &b) < 1e-10);
    for i in (0..a.dim()).filter(|&i| fixed[i]) {
        assert_eq!(x[i], b[i], "a fixed DOF keeps its right-hand side");
    }
}

#[test]
fn two_domain_factorisation_rejects_an_indefinite_matrix() {
    let mut rng = TestRng::new(12);
    let mut a = grid_block_spd(3, 3, 20, &mut rng);
    // A negative diagonal entry in the middle of the body (likely in the separator or
    // one domain) and one at the end: either way the factorisation must fail cleanly.
    let n = a.dim();
    a.add(n / 2, n / 2, -1e3);
    let solver = CholeskySolver::with_substructuring(a.pattern().clone(), Substructuring::Always).unwrap();
    assert!(matches!(solver.factorize(&a), Err(Error::NotPositiveDefinite)));
    let mut b = grid_block_spd(3, 3, 20, &mut rng);
    b.add(0, 0, -1e3);
    assert!(matches!(solver.factorize(&b), Err(Error::NotPositiveDefinite)));
}

#[test]
fn reused_factor_buffers_give_the_same_factor_bit_for_bit() {
    // A solver's dropped factors lend their buffers to its next factorisations. Factorise
    // A, drop it, factorise A again and keep it, then factorise B (more buffers than one
    // in play): B's solve must equal, bit for bit, that of B's factor from a fresh
    // solver — on the undivided and the two-domain path — and a clone of a factor must
    // solve as the factor does after the original is dropped.
    let mut rng = TestRng::new(12);
    let a = grid_block_spd(4, 5, 30, &mut rng);
    let mut b = a.clone();
    b.values_mut().iter_mut().for_each(|v| *v *= 1.5);
    b.add_diagonal(0.25);
    let n = a.dim();
    let rhs = rng.vec(n, -1.0, 1.0);
    let solve = |f: &CholeskyFactor| {
        let mut x = rhs.clone();
        f.solve_in_place(&mut x);
        x
    };
    for sub in [Substructuring::Never, Substructuring::Always] {
        let used = CholeskySolver::with_substructuring(a.pattern().clone(), sub).unwrap();
        drop(used.factorize(&a).unwrap());
        let kept = used.factorize(&a).unwrap();
        let from_reused = used.factorize(&b).unwrap();
        let fresh = CholeskySolver::with_substructuring(a.pattern().clone(), sub)
            .unwrap()
            .factorize(&b)
            .unwrap();
        assert_eq!(solve(&from_reused), solve(&fresh), "{sub:?}");
        let x_kept = solve(&kept);
        let copy = kept.clone();
        drop(kept);
        drop(used.factorize(&b).unwrap());
        assert_eq!(solve(&copy), x_kept, "{sub:?}: the clone");
        assert!(max_residual(&a, &x_kept, &rhs) < 1e-10);
    }
}
