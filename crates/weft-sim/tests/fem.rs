//! Volumetric FEM: materials, integrators and solves (weft-sim II).

use std::sync::Arc;

use nalgebra::{Rotation3, Vector3};
use weft_linalg::{SymmetricMatrix, SymmetricPattern};
use weft_mesh::generators::{beam, BeamParams};
use weft_mesh::TetMesh;
use weft_sim::anchors::{fixed_dofs, hold, nodes_at_min};
use weft_sim::energies::{ConstantForce, LameParameters, Material, TetElasticity};
use weft_sim::{
    Energy, Error, ImplicitEuler, LinearSolve, Newmark, PrefactorizedLinear, Quasistatic, RayleighDamping,
};
use weft_testkit::{assert_close, fd_gradient, fd_jacobian, max_norm_rel_error, TestRng};

fn lame(young: f64, poisson: f64) -> LameParameters {
    LameParameters::from_young_poisson(young, poisson).unwrap()
}

fn small_beam() -> TetMesh {
    beam(&BeamParams { cells: [2, 1, 1], size: [0.2, 0.1, 0.1] }).unwrap()
}

fn gradient(e: &dyn Energy, x: &[f64]) -> Vec<f64> {
    let mut g = vec![0.0; x.len()];
    e.add_gradient(x, &mut g);
    g
}

fn dense_hessian(e: &dyn Energy, x: &[f64], project: bool) -> Vec<Vec<f64>> {
    let mut pairs = Vec::new();
    e.hessian_pairs(&mut pairs);
    let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(x.len() / 3, pairs));
    let mut h = SymmetricMatrix::zeros(pattern);
    e.add_hessian(x, project, &mut h);
    (0..x.len()).map(|r| (0..x.len()).map(|c| h.get(r, c)).collect()).collect()
}

/// Rest positions plus a random deformation of relative size `scale`.
fn deformed(mesh: &TetMesh, scale: f64, seed: u64) -> Vec<f64> {
    let mut rng = TestRng::new(seed);
    mesh.flat_positions().iter().map(|x| x + scale * rng.uniform(-0.1, 0.1)).collect()
}

#[test]
fn lame_conversion_and_validation() {
    let l = lame(1e5, 0.3);
    assert_close!(l.mu, 1e5 / 2.6, rtol = 1e-14, atol = 0.0);
    assert_close!(l.lambda, 1e5 * 0.3 / (1.3 * 0.4), rtol = 1e-14, atol = 0.0);
    assert_close!(l.young(), 1e5, rtol = 1e-12, atol = 0.0);
    assert_close!(l.poisson(), 0.3, rtol = 1e-12, atol = 0.0);
    for (e, nu) in [(0.0, 0.3), (-1.0, 0.3), (f64::NAN, 0.3), (1e5, 0.5), (1e5, -0.1), (1e5, f64::INFINITY)] {
        assert!(matches!(LameParameters::from_young_poisson(e, nu), Err(Error::InvalidParameter { .. })), "E {e} ν {nu}");
    }
    let zero = lame(1e5, 0.0);
    assert_eq!(zero.lambda, 0.0);
}

#[test]
fn gradients_match_finite_differences_for_every_material() {
    let mesh = small_beam();
    for material in Material::ALL {
        let energy = TetElasticity::new(&mesh, material, lame(1e4, 0.3)).unwrap();
        for seed in 0..3 {
            let x = deformed(&mesh, 0.3, seed);
            let g = gradient(&energy, &x);
            let fd = fd_gradient(|y| energy.value(y), &x, 1e-6);
            let err = max_norm_rel_error(&g, &fd);
            assert!(err < 1e-6, "{material:?} seed {seed}: gradient error {err:e}");
        }
    }
}

#[test]
fn hessians_match_finite_differences_for_every_material() {
    let mesh = small_beam();
    for material in Material::ALL {
        let energy = TetElasticity::new(&mesh, material, lame(1e4, 0.3)).unwrap();
        for seed in 0..3 {
            let x = deformed(&mesh, 0.3, 10 + seed);
            let h = dense_hessian(&energy, &x, false);
            let fd = fd_jacobian(|y| gradient(&energy, y), &x, 1e-6);
            let err = max_norm_rel_error(&h.concat(), &fd.concat());
            assert!(err < 1e-6, "{material:?} seed {seed}: Hessian error {err:e}");
        }
    }
}

#[test]
fn projected_hessians_are_positive_semidefinite() {
    let mesh = small_beam();
    for material in Material::ALL {
        let energy = TetElasticity::new(&mesh, material, lame(1e4, 0.45)).unwrap();
        // A strong compression makes StVK, co-rotational and Neo-Hookean indefinite.
        let x: Vec<f64> = deformed(&mesh, 0.5, 3).chunks(3).flat_map(|p| [0.4 * p[0], p[1], p[2]]).collect();
        let h = dense_hessian(&energy, &x, true);
        let n = x.len();
        let m = nalgebra::DMatrix::from_fn(n, n, |r, c| h[r][c]);
        let scale = m.amax();
        let min = m.symmetric_eigen().eigenvalues.min();
        assert!(min > -1e-10 * scale, "{material:?}: projected Hessian has eigenvalue {min:e} (scale {scale:e})");
    }
}

#[test]
fn all_materials_agree_with_linear_elasticity_for_infinitesimal_strain() {
    let mesh = small_beam();
    let rest = mesh.flat_positions();
    let linear = TetElasticity::new(&mesh, Material::Linear, lame(1e4, 0.3)).unwrap();
    let k_lin = dense_hessian(&linear, &rest, false).concat();
    let x = deformed(&mesh, 1e-5, 42);
    let (e_lin, g_lin) = (linear.value(&x), gradient(&linear, &x));
    assert!(e_lin > 0.0);
    for material in [Material::CoRotational, Material::StVK, Material::NeoHookean] {
        let energy = TetElasticity::new(&mesh, material, lame(1e4, 0.3)).unwrap();
        // Same stiffness at rest …
        let k = dense_hessian(&energy, &rest, false).concat();
        assert!(max_norm_rel_error(&k, &k_lin) < 1e-10, "{material:?}: rest stiffness differs");
        // … and the same energy and forces up to O(strain) relative error.
        assert_close!(energy.value(&x), e_lin, rtol = 1e-4, atol = 0.0);
        let err = max_norm_rel_error(&gradient(&energy, &x), &g_lin);
        assert!(err < 1e-4, "{material:?}: small-strain force error {err:e}");
        // Zero energy and force at rest.
        assert_close!(energy.value(&rest), 0.0, rtol = 0.0, atol = 1e-18);
        assert!(gradient(&energy, &rest).iter().all(|g| g.abs() < 1e-9));
    }
}

fn rotate(x: &[f64], r: &Rotation3<f64>) -> Vec<f64> {
    x.chunks(3).flat_map(|p| (r * Vector3::new(p[0], p[1], p[2])).iter().copied().collect::<Vec<_>>()).collect()
}

#[test]
fn nonlinear_energies_are_rotation_invariant() {
    let mesh = small_beam();
    let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(Vector3::new(1.0, 2.0, -0.5)), 2.1);
    for material in [Material::CoRotational, Material::StVK, Material::NeoHookean] {
        let energy = TetElasticity::new(&mesh, material, lame(1e4, 0.3)).unwrap();
        let x = deformed(&mesh, 0.3, 5);
        let e = energy.value(&x);
        assert!(e > 0.0);
        assert_close!(energy.value(&rotate(&x, &r)), e, rtol = 1e-10, atol = 0.0);
        // Forces rotate with the body.
        let g_rot = gradient(&energy, &rotate(&x, &r));
        let g = rotate(&gradient(&energy, &x), &r);
        assert!(max_norm_rel_error(&g_rot, &g) < 1e-9, "{material:?}: forces not equivariant");
        // A rigid rotation of the rest shape costs nothing.
        assert_close!(energy.value(&rotate(&mesh.flat_positions(), &r)), 0.0, rtol = 0.0, atol = 1e-9 * e);
    }
}

#[test]
fn linear_elasticity_shows_its_rotation_artefact() {
    // A rigid rotation by θ about z has Cauchy strain diag(cos θ − 1, cos θ − 1, 0), so
    // Ψ = (2μ + 2λ)(1 − cos θ)² per unit volume — energy for a motion that should cost none.
    let mesh = small_beam();
    let l = lame(1e4, 0.3);
    let energy = TetElasticity::new(&mesh, Material::Linear, l).unwrap();
    for theta in [0.1f64, 0.5, 1.5] {
        let x = rotate(&mesh.flat_positions(), &Rotation3::from_axis_angle(&Vector3::z_axis(), theta));
        let expected = mesh.volume() * (2.0 * l.mu + 2.0 * l.lambda) * (1.0 - theta.cos()).powi(2);
        assert!(expected > 0.0);
        assert_close!(energy.value(&x), expected, rtol = 1e-10, atol = 0.0);
    }
}

fn single_tet(flip: bool) -> (TetMesh, Vec<f64>) {
    let rest = vec![Vector3::zeros(), Vector3::new(1.0, 0.0, 0.0), Vector3::new(0.0, 1.0, 0.0), Vector3::new(0.0, 0.0, 1.0)];
    let mesh = TetMesh::new(rest, vec![[0, 1, 2, 3]]).unwrap();
    let mut x = mesh.flat_positions();
    if flip {
        // Push the apex through the opposite face: det F = −0.5.
        x[11] = -0.5;
    }
    (mesh, x)
}

#[test]
fn inverted_tet_gives_finite_energy_forces_and_stiffness() {
    let (mesh, x) = single_tet(true);
    for material in Material::ALL {
        let energy = TetElasticity::new(&mesh, material, lame(1e4, 0.45)).unwrap();
        assert!(energy.deformation_gradient(&x, 0).determinant() < 0.0);
        let e = energy.value(&x);
        assert!(e.is_finite() && e > 0.0, "{material:?}: energy {e}");
        let g = gradient(&energy, &x);
        assert!(g.iter().all(|v| v.is_finite()), "{material:?}: gradient {g:?}");
        for project in [false, true] {
            assert!(dense_hessian(&energy, &x, project).concat().iter().all(|v| v.is_finite()));
        }
        // A completely flat element (det F = 0) too.
        let mut flat = x.clone();
        flat[11] = 0.0;
        assert!(energy.value(&flat).is_finite());
        assert!(gradient(&energy, &flat).iter().all(|v| v.is_finite()));
    }
}

#[test]
fn neo_hookean_extension_is_smooth_and_pushes_towards_uninversion() {
    let (mesh, x) = single_tet(true);
    let energy = TetElasticity::new(&mesh, Material::NeoHookean, lame(1e4, 0.45)).unwrap();
    // Derivatives stay exact in the extended region …
    let err = max_norm_rel_error(&gradient(&energy, &x), &fd_gradient(|y| energy.value(y), &x, 1e-6));
    assert!(err < 1e-6, "gradient error {err:e}");
    let h = dense_hessian(&energy, &x, false).concat();
    let fd = fd_jacobian(|y| gradient(&energy, y), &x, 1e-6).concat();
    assert!(max_norm_rel_error(&h, &fd) < 1e-6);
    // … and the force on the apex points back up (towards positive volume).
    assert!(gradient(&energy, &x)[11] < 0.0);
    // Newton from the inverted state un-inverts the element (base pinned).
    let fixed = fixed_dofs(4, &[0, 1, 2]).unwrap();
    let mut qs = Quasistatic::new(12, &[&energy], fixed).unwrap();
    let mut y = x.clone();
    qs.solve(&[&energy], &[0.0; 12], &mut y, 1).unwrap();
    assert!(energy.deformation_gradient(&y, 0).determinant() > 0.99);
}

#[test]
fn serial_and_parallel_assembly_are_bit_identical() {
    let mesh = beam(&BeamParams { cells: [12, 4, 4], size: [1.0, 0.3, 0.3] }).unwrap();
    let x = deformed(&mesh, 0.2, 9);
    for material in Material::ALL {
        let mut energy = TetElasticity::new(&mesh, material, lame(1e5, 0.4)).unwrap();
        energy.set_parallel(false);
        let (e0, g0, h0) = (energy.value(&x), gradient(&energy, &x), dense_hessian(&energy, &x, true));
        energy.set_parallel(true);
        assert_eq!(energy.value(&x).to_bits(), e0.to_bits());
        assert_eq!(gradient(&energy, &x), g0);
        assert_eq!(dense_hessian(&energy, &x, true), h0);
    }
}

/// Tip deflection of a clamped cantilever `[8n, n, n]` cells over 1 × 0.1 × 0.1 m with
/// total tip load `force` (N) along −z spread over the tip face by area.
fn cantilever_deflection(n: usize, young: f64, force: f64, material: Option<Material>) -> f64 {
    let mesh = beam(&BeamParams { cells: [8 * n, n, n], size: [1.0, 0.1, 0.1] }).unwrap();
    let nv = mesh.num_vertices();
    let anchors = nodes_at_min(mesh.positions(), 0, 1e-9).unwrap();
    let fixed = fixed_dofs(nv, &anchors).unwrap();
    let tip: Vec<usize> = (0..nv).filter(|&i| (mesh.positions()[i].x - 1.0).abs() < 1e-9).collect();
    let mut load = vec![0.0; 3 * nv];
    let tip_faces: Vec<[usize; 3]> =
        mesh.boundary_faces().into_iter().filter(|f| f.iter().all(|v| tip.contains(v))).collect();
    for f in &tip_faces {
        let p = f.map(|v| mesh.positions()[v]);
        let area = weft_mesh::geometry::triangle_area(&p[0], &p[1], &p[2]);
        for &v in f {
            load[3 * v + 2] -= force * area / (3.0 * 0.01);
        }
    }
    assert_close!(load.iter().sum::<f64>(), -force, rtol = 1e-12, atol = 0.0);
    let rest = mesh.flat_positions();
    let lin = TetElasticity::new(&mesh, material.unwrap_or(Material::Linear), lame(young, 0.0)).unwrap();
    let u: Vec<f64> = match material {
        None => {
            let mut solver =
                PrefactorizedLinear::new(&rest, &[&lin], vec![0.0; nv], fixed, LinearSolve::Static).unwrap();
            solver.step(&load, &[]).unwrap();
            solver.displacements().to_vec()
        }
        Some(_) => {
            let mut qs = Quasistatic::new(3 * nv, &[&lin], fixed).unwrap();
            let mut x = rest.clone();
            qs.solve(&[&lin], &load, &mut x, 2).unwrap();
            x.iter().zip(&rest).map(|(x, r)| x - r).collect()
        }
    };
    -tip.iter().map(|&v| u[3 * v + 2]).sum::<f64>() / tip.len() as f64
}

#[test]
fn cantilever_matches_euler_bernoulli_and_converges_under_refinement() {
    let (young, force) = (1e7, 1.0);
    let inertia = 0.1f64.powi(4) / 12.0;
    let exact = force / (3.0 * young * inertia);
    let coarse = cantilever_deflection(2, young, force, None);
    let fine = cantilever_deflection(4, young, force, None);
    let (err_coarse, err_fine) = ((coarse - exact).abs() / exact, (fine - exact).abs() / exact);
    println!("Euler–Bernoulli δ = {exact:e} m; n=2: {coarse:e} ({err_coarse:.3}), n=4: {fine:e} ({err_fine:.3})");
    // Linear tets are too stiff in bending (shear locking): approached from below …
    assert!(coarse < fine && fine < exact * 1.05);
    // … and the error falls at least like h (first-order element) as the mesh halves.
    assert!(err_fine < 0.6 * err_coarse, "errors {err_coarse} → {err_fine}");
    assert!(err_fine < 0.25, "fine-mesh error {err_fine}");
    // A small load: StVK and Neo-Hookean (quasistatic Newton) give the linear answer.
    for material in [Material::StVK, Material::NeoHookean, Material::CoRotational] {
        let nonlinear = cantilever_deflection(2, young, force, Some(material));
        assert_close!(nonlinear, coarse, rtol = 1e-3, atol = 0.0);
    }
}
