//! Integration tests of weft-mesh: validation, topology, geometry, generators, I/O.

use std::path::Path;

use nalgebra::Vector3;
use weft_mesh::geometry::*;
use weft_mesh::io::*;
use weft_mesh::{Error, TetMesh, TetTopology, Topology, TriMesh, generators};
use weft_testkit::{TestRng, assert_close};

fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

/// Two right triangles forming the unit square: (0,1,2), (0,2,3).
fn square() -> TriMesh {
    TriMesh::new(
        vec![v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)],
        vec![[0, 1, 2], [0, 2, 3]],
    )
    .unwrap()
}

fn tmp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("weft-mesh-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

// ---------------------------------------------------------------- validation

#[test]
fn validation_names_each_kind_of_bad_input() {
    let p = vec![v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.)];
    assert!(matches!(TriMesh::new(vec![], vec![[0, 1, 2]]), Err(Error::NoVertices)));
    assert!(matches!(TriMesh::new(p.clone(), vec![]), Err(Error::NoElements { .. })));
    assert!(matches!(
        TriMesh::new(p.clone(), vec![[0, 1, 3]]),
        Err(Error::IndexOutOfRange {
            index: 0,
            vertex: 3,
            num_vertices: 3,
            ..
        })
    ));
    assert!(matches!(
        TriMesh::new(p.clone(), vec![[0, 1, 1]]),
        Err(Error::RepeatedIndex { vertex: 1, .. })
    ));
    let mut bad = p.clone();
    bad[1].y = f64::NAN;
    assert!(matches!(
        TriMesh::new(bad, vec![[0, 1, 2]]),
        Err(Error::NonFiniteCoordinate { vertex: 1, .. })
    ));
    let mut inf = p.clone();
    inf[2].z = f64::INFINITY;
    assert!(matches!(
        TriMesh::new(inf, vec![[0, 1, 2]]),
        Err(Error::NonFiniteCoordinate { vertex: 2, .. })
    ));
}

#[test]
fn three_faces_on_an_edge_is_non_manifold() {
    let p = vec![
        v(0., 0., 0.),
        v(1., 0., 0.),
        v(0., 1., 0.),
        v(0., -1., 0.),
        v(0., 0., 1.),
    ];
    let e = TriMesh::new(p, vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]]).unwrap_err();
    assert!(matches!(e, Error::NonManifoldEdge { a: 0, b: 1, count: 3 }), "{e}");
}

#[test]
fn flipped_face_is_inconsistent_orientation() {
    let p = vec![v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)];
    let e = TriMesh::new(p, vec![[0, 1, 2], [0, 3, 2]]).unwrap_err();
    assert!(matches!(e, Error::InconsistentOrientation { a: 0, b: 2 }), "{e}");
}

#[test]
fn zero_area_face_is_reported_where_area_is_needed() {
    let m = TriMesh::new(vec![v(0., 0., 0.), v(1., 0., 0.), v(2., 0., 0.)], vec![[0, 1, 2]]).unwrap();
    assert!(matches!(
        m.check_face_areas(1e-12),
        Err(Error::DegenerateFace { face: 0, .. })
    ));
    let topo = Topology::new(&m);
    assert!(matches!(
        cotangent_weights(m.positions(), m.faces(), &topo),
        Err(Error::DegenerateFace { .. })
    ));
    assert!(square().check_face_areas(1e-12).is_ok());
}

#[test]
fn inverted_and_flat_tets_are_rejected() {
    let p = vec![v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.), v(0., 0., 1.)];
    assert!(TetMesh::new(p.clone(), vec![[0, 1, 2, 3]]).is_ok());
    let e = TetMesh::new(p.clone(), vec![[0, 2, 1, 3]]).unwrap_err();
    assert!(
        matches!(e, Error::BadTetVolume { tet: 0, volume } if volume < 0.0),
        "{e}"
    );
    assert!(e.to_string().contains("inverted"));
    let flat = vec![v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.), v(1., 1., 0.)];
    let e = TetMesh::new(flat, vec![[0, 1, 2, 3]]).unwrap_err();
    assert!(e.to_string().contains("zero volume"), "{e}");
}

#[test]
fn random_garbage_never_panics() {
    // Fuzz-like: random positions (some non-finite) and random index triples/quads.
    let mut rng = TestRng::new(42);
    for round in 0..2000 {
        let nv = (rng.uniform(0.0, 8.0)) as usize;
        let mut p: Vec<Vector3<f64>> = (0..nv)
            .map(|_| v(rng.uniform(-1., 1.), rng.uniform(-1., 1.), rng.uniform(-1., 1.)))
            .collect();
        if round % 7 == 0 && nv > 0 {
            p[0].x = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY][round % 3];
        }
        let nf = (rng.uniform(0.0, 6.0)) as usize;
        let faces: Vec<[usize; 3]> = (0..nf)
            .map(|_| [0; 3].map(|_| rng.uniform(0.0, 9.0) as usize))
            .collect();
        let tets: Vec<[usize; 4]> = (0..nf)
            .map(|_| [0; 4].map(|_| rng.uniform(0.0, 9.0) as usize))
            .collect();
        if let Ok(m) = TriMesh::new(p.clone(), faces) {
            let t = Topology::new(&m);
            let _ = cotangent_weights(m.positions(), m.faces(), &t);
            let _ = dihedral_angles(m.positions(), &t);
            let _ = m.euler_characteristic();
        }
        if let Ok(m) = TetMesh::new(p, tets) {
            let _ = m.boundary_surface();
            let _ = TetTopology::new(&m);
        }
    }
}

// ---------------------------------------------------------------- topology

#[test]
fn square_topology_by_hand() {
    let m = square();
    let t = Topology::new(&m);
    assert_eq!(t.edges, vec![[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]);
    assert_eq!(t.hinges.len(), 1);
    let h = t.hinges[0];
    assert_eq!(t.edges[h.edge], [0, 2]);
    // Face 0 = (0,1,2) traverses 2 → 0; its opposite vertex is 1, the other face's is 3.
    assert_eq!(h.edge_vertices, [2, 0]);
    assert_eq!(h.opposite, [1, 3]);
    assert_eq!(t.one_ring.neighbors(1), &[0, 2]);
    assert_eq!(t.one_ring.neighbors(0), &[1, 2, 3]);
    assert_eq!(t.two_ring.neighbors(1), &[3]);
    assert_eq!(t.two_ring.neighbors(0), &[] as &[usize]);
    assert_eq!(t.boundary_loops.len(), 1);
    assert_eq!(t.boundary_loops[0].len(), 4);
    assert_eq!(t.boundary_edges().count(), 4);
    assert_eq!(t.vertex_faces.neighbors(0), &[0, 1]);
    // Edge → faces and face → edges agree: the diagonal has both faces, the sides one each.
    assert_eq!(t.edge_faces[1], [Some(0), Some(1)]);
    for e in [0, 2, 3, 4] {
        assert!(t.edge_faces[e][0].is_some() && t.edge_faces[e][1].is_none());
    }
    for (f, fe) in t.face_edges.iter().enumerate() {
        for (k, &e) in fe.iter().enumerate() {
            let (a, b) = (m.faces()[f][k], m.faces()[f][(k + 1) % 3]);
            assert_eq!(t.edges[e], [a.min(b), a.max(b)]);
            assert!(t.edge_faces[e].contains(&Some(f)));
        }
    }
}

#[test]
fn vertex_normals_of_a_ball_point_outward_along_the_radius() {
    let ball = generators::ball(48, 32, 0.5).unwrap();
    let normals = vertex_normals(ball.positions(), ball.faces());
    for (p, n) in ball.positions().iter().zip(&normals) {
        assert_close!(n.norm(), 1.0, rtol = 1e-12, atol = 0.0);
        // Area-weighted normals of a fine UV sphere are within ~1° of the radius.
        assert!(n.dot(&p.normalize()) > 0.9998, "normal {n:?} at {p:?}");
    }
    // A flat sheet's vertex normals are all +Z.
    let s = generators::sheet(5, 1.0).unwrap();
    assert!(
        vertex_normals(s.positions(), s.faces())
            .iter()
            .all(|n| (n - v(0., 0., 1.)).norm() < 1e-12)
    );
}

#[test]
fn two_ring_excludes_vertex_and_one_ring_on_the_grid() {
    let m = generators::sheet(5, 1.0).unwrap();
    let t = Topology::new(&m);
    for i in 0..m.num_vertices() {
        let r1 = t.one_ring.neighbors(i);
        for &j in t.two_ring.neighbors(i) {
            assert_ne!(i, j);
            assert!(!r1.contains(&j));
            // Exactly two edges away: a common neighbour exists.
            assert!(r1.iter().any(|&k| t.one_ring.neighbors(k).contains(&j)));
        }
        // Symmetric relation.
        for &j in t.two_ring.neighbors(i) {
            assert!(t.two_ring.neighbors(j).contains(&i));
        }
    }
}

#[test]
fn boundary_loops_count_holes() {
    let sheet = generators::sheet(17, 1.0).unwrap();
    assert_eq!(Topology::new(&sheet).boundary_loops.len(), 1);
    let holes = generators::sheet_with_holes(65, 1.0, &generators::DEFAULT_HOLES).unwrap();
    let t = Topology::new(&holes);
    assert_eq!(t.boundary_loops.len(), 3, "outer boundary + 2 holes");
    // Every boundary edge is used by exactly one loop.
    let total: usize = t.boundary_loops.iter().map(Vec::len).sum();
    assert_eq!(total, t.boundary_edges().count());
    let ball = generators::ball(48, 32, 0.5).unwrap();
    assert!(Topology::new(&ball).boundary_loops.is_empty());
}

#[test]
fn euler_characteristic_of_generated_meshes() {
    assert_eq!(generators::sheet(33, 1.0).unwrap().euler_characteristic(), 1);
    assert_eq!(generators::ball(48, 32, 0.5).unwrap().euler_characteristic(), 2);
    // A disc with k holes: χ = 1 − k.
    assert_eq!(
        generators::sheet_with_holes(65, 1.0, &generators::DEFAULT_HOLES)
            .unwrap()
            .euler_characteristic(),
        -1
    );
    // Tet boundary of a box is a sphere.
    let beam = generators::beam(&generators::BeamParams::default()).unwrap();
    assert_eq!(beam.boundary_surface().unwrap().mesh.euler_characteristic(), 2);
}

#[test]
fn tet_topology_and_boundary_of_one_cube() {
    let cube = generators::beam(&generators::BeamParams {
        cells: [1, 1, 1],
        size: [1.0, 1.0, 1.0],
    })
    .unwrap();
    assert_eq!(cube.num_tets(), 6);
    assert_eq!(cube.num_vertices(), 8);
    let t = TetTopology::new(&cube);
    // 12 cube edges + 6 face diagonals + 1 body diagonal.
    assert_eq!(t.edges.len(), 19);
    let s = cube.boundary_surface().unwrap();
    assert_eq!(s.mesh.num_faces(), 12);
    assert_close!(s.mesh.area(), 6.0, rtol = 1e-12, atol = 0.0);
    // Outward orientation: the divergence theorem gives V = (1/3) Σ_f c_f · n_f A_f.
    let vol: f64 = s
        .mesh
        .faces()
        .iter()
        .map(|f| {
            let p = s.mesh.positions();
            let (a, b, c) = (p[f[0]], p[f[1]], p[f[2]]);
            (b - a).cross(&(c - a)).dot(&a) / 6.0
        })
        .sum();
    assert_close!(vol, 1.0, rtol = 1e-12, atol = 0.0);
}

// ---------------------------------------------------------------- geometry

#[test]
fn square_geometry_by_hand() {
    let m = square();
    assert_eq!(face_areas(m.positions(), m.faces()), vec![0.5, 0.5]);
    for n in face_normals(m.positions(), m.faces()) {
        assert_eq!(n, v(0., 0., 1.));
    }
    let masses = lumped_masses_tri(m.positions(), m.faces(), 2.0);
    // Vertices 0 and 2 touch both faces: 2 · (2 · 0.5 / 3); vertices 1 and 3 one face.
    assert_close!(masses[0], 2.0 / 3.0, rtol = 1e-14, atol = 0.0);
    assert_close!(masses[1], 1.0 / 3.0, rtol = 1e-14, atol = 0.0);
    let t = Topology::new(&m);
    let w = cotangent_weights(m.positions(), m.faces(), &t).unwrap();
    // Diagonal [0,2]: opposite right angles, cot = 0. Sides: one 45° angle, ½ cot 45° = ½.
    let diag = t.edges.iter().position(|e| *e == [0, 2]).unwrap();
    assert_close!(w[diag], 0.0, rtol = 0.0, atol = 1e-15);
    for (e, &wi) in w.iter().enumerate() {
        if e != diag {
            assert_close!(wi, 0.5, rtol = 1e-14, atol = 0.0);
        }
    }
}

#[test]
fn dihedral_angle_sign_and_value() {
    // Hinge along +X; x2 on +Y (first face normal +Z), x3 on −Y.
    let (x0, x1, x2) = (v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.));
    assert_close!(
        dihedral_angle(&x0, &x1, &x2, &v(0., -1., 0.)),
        0.0,
        rtol = 0.0,
        atol = 1e-15
    );
    for theta in [0.3f64, 1.0, 2.5, 3.0] {
        // Lift x3 along +Z (valley towards the normal): negative by our convention.
        let x3 = v(0., -theta.cos(), theta.sin());
        assert_close!(dihedral_angle(&x0, &x1, &x2, &x3), -theta, rtol = 1e-12, atol = 1e-14);
        let x3 = v(0., -theta.cos(), -theta.sin());
        assert_close!(dihedral_angle(&x0, &x1, &x2, &x3), theta, rtol = 1e-12, atol = 1e-14);
    }
}

#[test]
fn dihedral_angles_of_a_ball_are_all_convex() {
    let ball = generators::ball(48, 32, 0.5).unwrap();
    let t = Topology::new(&ball);
    let a = dihedral_angles(ball.positions(), &t);
    assert_eq!(a.len(), t.edges.len(), "closed surface: every edge is a hinge");
    let (lo, hi) = a
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x)));
    // Quad diagonals of the UV sphere are flat (planar trapezoids); every other hinge is
    // convex, which our sign convention makes positive.
    assert!(
        lo > -1e-12 && hi < 0.5,
        "convex surface has small non-negative angles, got [{lo}, {hi}]"
    );
    let convex = a.iter().filter(|&&x| x > 1e-3).count();
    assert_eq!(
        convex,
        t.edges.len() - 48 * 31,
        "all but the 48 × 31 quad diagonals are strictly convex"
    );
}

#[test]
fn cotangent_laplacian_rows_sum_to_zero_and_reproduce_linear_functions() {
    for m in [
        generators::sheet(17, 1.0).unwrap(),
        generators::ball(48, 32, 0.5).unwrap(),
    ] {
        let t = Topology::new(&m);
        let trip = cotangent_laplacian(m.positions(), m.faces(), &t).unwrap();
        let mut row = vec![0.0; m.num_vertices()];
        for &(r, _, val) in &trip {
            row[r] += val;
        }
        assert!(
            row.iter().all(|s| s.abs() < 1e-12),
            "row sums {:?}",
            row.iter().fold(0.0f64, |a, b| a.max(b.abs()))
        );
    }
    // On a flat sheet, L x = 0 at interior vertices for linear x (linear precision).
    let m = generators::sheet(9, 1.0).unwrap();
    let t = Topology::new(&m);
    let trip = cotangent_laplacian(m.positions(), m.faces(), &t).unwrap();
    let f: Vec<f64> = m.positions().iter().map(|p| 2.0 * p.x - 3.0 * p.y + 1.0).collect();
    let mut lf = vec![0.0; m.num_vertices()];
    for &(r, c, val) in &trip {
        lf[r] += val * f[c];
    }
    let boundary = t.boundary_vertices(m.num_vertices());
    for i in 0..m.num_vertices() {
        if !boundary[i] {
            assert!(lf[i].abs() < 1e-12);
        }
    }
}

#[test]
fn areas_and_volumes_sum_to_the_analytic_ones() {
    let s = generators::sheet(65, 2.0).unwrap();
    assert_close!(s.area(), 4.0, rtol = 1e-12, atol = 0.0);
    let masses = lumped_masses_tri(s.positions(), s.faces(), 0.3);
    assert_close!(masses.iter().sum::<f64>(), 1.2, rtol = 1e-12, atol = 0.0);
    let ball = generators::ball(48, 32, 0.5).unwrap();
    // An inscribed polyhedron: slightly less than 4πr², within 0.5 %.
    let sphere = 4.0 * std::f64::consts::PI * 0.25;
    assert!(ball.area() < sphere && ball.area() > 0.995 * sphere);
    let params = generators::BeamParams::default();
    let beam = generators::beam(&params).unwrap();
    assert_eq!(beam.num_tets(), 2592);
    assert_close!(beam.volume(), 0.25, rtol = 1e-12, atol = 0.0);
    let m = lumped_masses_tet(beam.positions(), beam.tets(), 1000.0);
    assert_close!(m.iter().sum::<f64>(), 250.0, rtol = 1e-12, atol = 0.0);
}

#[test]
fn rest_inverses_invert_shape_matrices() {
    let beam = generators::tapered_beam(&generators::BeamParams::default(), 0.5).unwrap();
    let inv = tet_rest_inverses(beam.positions(), beam.tets()).unwrap();
    for (t, di) in beam.tets().iter().zip(&inv) {
        let d = tet_shape_matrix(beam.positions(), t);
        assert!((d * di - nalgebra::Matrix3::identity()).norm() < 1e-10);
    }
}

#[test]
fn other_tet_shapes_are_valid_and_have_the_expected_volume() {
    let p = generators::BeamParams::default();
    let tapered = generators::tapered_beam(&p, 0.5).unwrap();
    // Cross-section scales linearly from 1 to 0.5: area factor ∫(1 − x/2)² dx over [0,1] = 7/12.
    assert_close!(tapered.volume(), 0.25 * 7.0 / 12.0, rtol = 1e-12, atol = 0.0);
    let bent = generators::bent_beam(&p, std::f64::consts::FRAC_PI_2).unwrap();
    // Pappus: the bent volume equals the straight one (centre line length is kept), less
    // the chord error: each cell's annular sector of angle φ becomes a trapezoid of area
    // ½(r_o² − r_i²) sin φ instead of ½(r_o² − r_i²) φ.
    let phi = std::f64::consts::FRAC_PI_2 / 12.0;
    assert_close!(bent.volume(), 0.25 * phi.sin() / phi, rtol = 1e-12, atol = 0.0);
    let t = generators::t_beam(&p).unwrap();
    // 6×6 cross-section: flange = top 2 rows × 6, web = middle 2 columns × 4 rows below.
    assert_close!(t.volume(), 0.25 * (12.0 + 8.0) / 36.0, rtol = 1e-12, atol = 0.0);
    assert!(
        generators::bent_beam(&p, 10.0).is_err(),
        "inner radius would be negative"
    );
}

#[test]
fn generator_sizes_match_the_papers() {
    assert_eq!(generators::sheet(65, 1.0).unwrap().num_vertices(), 4225);
    assert_eq!(generators::sheet(33, 1.0).unwrap().num_vertices(), 1089);
    assert_eq!(generators::sheet(17, 1.0).unwrap().num_vertices(), 289);
    assert_eq!(
        generators::sheet_with_holes(65, 1.0, &generators::DEFAULT_HOLES)
            .unwrap()
            .num_vertices(),
        4165
    );
    assert_eq!(generators::ball(48, 32, 0.5).unwrap().num_vertices(), 1538);
    assert!(generators::sheet(1, 1.0).is_err());
    assert!(generators::ball(2, 3, 1.0).is_err());
    assert!(generators::sheet(5, f64::NAN).is_err());
}

#[test]
fn geodesic_distance_on_a_grid_is_manhattan_on_axes() {
    let m = generators::sheet(11, 1.0).unwrap();
    let t = Topology::new(&m);
    let d = weft_mesh::geodesic::geodesic_distances(m.positions(), &t.one_ring, &[0]).unwrap();
    assert_eq!(d[0], 0.0);
    // Along the boundary row the path is straight.
    assert_close!(d[10], 1.0, rtol = 1e-12, atol = 0.0);
    // The far corner: at least the Euclidean distance, at most Manhattan.
    assert!(d[120] >= 2f64.sqrt() - 1e-12 && d[120] <= 2.0 + 1e-12);
    // Triangle inequality on every edge.
    for &[a, b] in &t.edges {
        let l = (m.positions()[a] - m.positions()[b]).norm();
        assert!((d[a] - d[b]).abs() <= l + 1e-12);
    }
    assert!(weft_mesh::geodesic::geodesic_distances(m.positions(), &t.one_ring, &[999]).is_err());
}

// ---------------------------------------------------------------- I/O

#[test]
fn obj_round_trip_is_exact() {
    let m = generators::ball(12, 6, 0.7).unwrap();
    let path = tmp("ball.obj");
    write_obj(&path, m.positions(), m.faces()).unwrap();
    let back = read_obj(&path).unwrap();
    assert_eq!(back, m);
}

#[test]
fn obj_reader_triangulates_polygons_and_accepts_slash_forms() {
    let text = "# quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n";
    let m = parse_obj(text, Path::new("quad.obj")).unwrap();
    assert_eq!(m.faces(), &[[0, 1, 2], [0, 2, 3]]);
    let rel = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n", Path::new("rel.obj")).unwrap();
    assert_eq!(rel.faces(), &[[0, 1, 2]]);
}

#[test]
fn bad_obj_files_give_line_numbered_errors() {
    let truncated = "v 0 0 0\nv 1 0 0\nv 0 1";
    let e = parse_obj(truncated, Path::new("t.obj")).unwrap_err();
    assert!(matches!(e, Error::Parse { line: 3, .. }), "{e}");
    assert!(e.to_string().contains("t.obj:3"));
    let out_of_range = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n";
    let e = parse_obj(out_of_range, Path::new("r.obj")).unwrap_err();
    assert!(
        matches!(e, Error::Parse { line: 4, .. }) && e.to_string().contains("out of range"),
        "{e}"
    );
    let nan = "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n";
    assert!(matches!(
        parse_obj(nan, Path::new("n.obj")),
        Err(Error::NonFiniteCoordinate { vertex: 1, .. })
    ));
    let junk = "v 0 0 zero\n";
    assert!(matches!(
        parse_obj(junk, Path::new("j.obj")),
        Err(Error::Parse { line: 1, .. })
    ));
    assert!(matches!(
        read_obj(Path::new("/nonexistent/x.obj")),
        Err(Error::Io { .. })
    ));
}

#[test]
fn tetgen_round_trip_and_one_based_files() {
    let beam = generators::t_beam(&generators::BeamParams {
        cells: [4, 3, 3],
        size: [1.0, 0.3, 0.3],
    })
    .unwrap();
    let path = tmp("tbeam.node");
    write_tetgen(&path, &beam).unwrap();
    let back = read_tetgen(&path.with_extension("ele")).unwrap();
    assert_eq!(back, beam);
    // A 1-based file as TetGen writes by default.
    let node = tmp("one.node");
    std::fs::write(&node, "4 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n").unwrap();
    std::fs::write(node.with_extension("ele"), "1 4 0\n1 1 2 3 4\n").unwrap();
    let m = read_tetgen(&node).unwrap();
    assert_eq!(m.tets(), &[[0, 1, 2, 3]]);
    // Truncated and out-of-range files.
    std::fs::write(node.with_extension("ele"), "2 4 0\n1 1 2 3 4\n").unwrap();
    assert!(matches!(read_tetgen(&node), Err(Error::Parse { .. })));
    std::fs::write(node.with_extension("ele"), "1 4 0\n1 1 2 3 5\n").unwrap();
    let e = read_tetgen(&node).unwrap_err();
    assert!(e.to_string().contains("out of range"), "{e}");
}

#[test]
fn ply_and_vtk_writers_produce_well_formed_files() {
    let m = square();
    let ply = tmp("sq.ply");
    write_ply(&ply, m.positions(), m.faces(), Some(&[[255, 0, 0]; 4])).unwrap();
    let text = std::fs::read_to_string(&ply).unwrap();
    assert!(text.contains("element vertex 4") && text.contains("property uchar red"));
    assert_eq!(text.lines().filter(|l| l.starts_with("3 ")).count(), 2);
    assert!(write_ply(&ply, m.positions(), m.faces(), Some(&[[0, 0, 0]; 3])).is_err());
    let beam = generators::beam(&generators::BeamParams {
        cells: [2, 1, 1],
        size: [2.0, 1.0, 1.0],
    })
    .unwrap();
    let vtk = tmp("beam.vtk");
    let disp = vec![0.0; 3 * beam.num_vertices()];
    write_vtk_tets(&vtk, beam.positions(), beam.tets(), &[("displacement", 3, &disp)]).unwrap();
    let text = std::fs::read_to_string(&vtk).unwrap();
    assert!(text.contains(&format!("CELLS {} {}", beam.num_tets(), 5 * beam.num_tets())));
    assert!(text.contains("VECTORS displacement double"));
    assert_eq!(text.lines().filter(|l| *l == "10").count(), beam.num_tets());
}

#[test]
fn read_mesh_dispatches_on_extension() {
    let path = tmp("s.obj");
    write_surface(&path, &generators::sheet(3, 1.0).unwrap()).unwrap();
    assert!(matches!(read_mesh(&path), Ok(AnyMesh::Surface(_))));
    let e = read_mesh(Path::new("x.stl")).unwrap_err();
    assert!(matches!(e, Error::UnsupportedFormat { .. }), "{e}");
}

#[test]
fn vtk_tet_round_trip_and_bad_files() {
    let beam = generators::bent_beam(
        &generators::BeamParams {
            cells: [4, 2, 2],
            size: [1.0, 0.2, 0.2],
        },
        0.8,
    )
    .unwrap();
    let path = tmp("bent.vtk");
    write_vtk_tets(&path, beam.positions(), beam.tets(), &[]).unwrap();
    let back = read_vtk_tets(&path).unwrap();
    assert_eq!(back, beam);
    assert!(matches!(read_mesh(&path), Ok(AnyMesh::Volume(_))));
    let tri = tmp("tri.vtk");
    write_vtk_triangles(&tri, square().positions(), square().faces(), &[]).unwrap();
    let e = read_vtk_tets(&tri).unwrap_err();
    assert!(e.to_string().contains("no tetrahedra"), "{e}");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&tri, &text[..text.len() / 3]).unwrap();
    assert!(matches!(read_vtk_tets(&tri), Err(Error::Parse { .. })));
}

#[test]
fn tube_is_an_open_cylinder_with_outward_faces() {
    let (around, rings) = (12, 5);
    let m = generators::tube(around, rings, 0.1, 0.5, |x| 0.05 + 0.02 * x).unwrap();
    assert_eq!(m.num_vertices(), around * rings);
    assert_eq!(m.num_faces(), 2 * around * (rings - 1));
    // An open cylinder: V − E + F = 0, and two boundary loops of `around` vertices.
    assert_eq!(m.euler_characteristic(), 0);
    let t = Topology::new(&m);
    let boundary = t.boundary_vertices(m.num_vertices());
    assert_eq!(boundary.iter().filter(|b| **b).count(), 2 * around);
    // Every face normal points away from the X axis.
    let p = m.positions();
    for f in m.faces() {
        let n = triangle_normal(&p[f[0]], &p[f[1]], &p[f[2]]);
        let c = (p[f[0]] + p[f[1]] + p[f[2]]) / 3.0;
        let radial = Vector3::new(0.0, c.y, c.z).normalize();
        assert!(n.dot(&radial) > 0.9, "face {f:?} normal {n:?}");
    }
    // Ring radii follow the profile.
    for k in 0..rings {
        let x = 0.1 + 0.4 * k as f64 / (rings - 1) as f64;
        let q = p[k * around + 3];
        assert_close!(
            (q.y * q.y + q.z * q.z).sqrt(),
            0.05 + 0.02 * x,
            rtol = 1e-12,
            atol = 0.0
        );
    }
    assert!(generators::tube(2, 5, 0.0, 1.0, |_| 1.0).is_err());
    assert!(generators::tube(8, 5, 1.0, 0.0, |_| 1.0).is_err());
    assert!(generators::tube(8, 5, 0.0, 1.0, |_| -1.0).is_err());
}

#[test]
fn generators_refuse_sizes_beyond_their_limit_with_an_error_not_an_abort() {
    use generators::{BeamParams, MAX_GENERATED_VERTICES};
    let too_large = |e: Error| matches!(&e, Error::InvalidParameter(m) if m.contains("more than"));
    // 4096² = 2²⁴ vertices is the limit itself; one more per side is beyond it.
    assert!(too_large(generators::sheet(4097, 1.0).unwrap_err()));
    assert!(too_large(generators::sheet(100_000, 1.0).unwrap_err()));
    // Products that overflow usize are refused the same way.
    assert!(too_large(generators::sheet(usize::MAX / 2, 1.0).unwrap_err()));
    assert!(too_large(generators::ball(1_000_000, 1_000_000, 0.5).unwrap_err()));
    assert!(too_large(
        generators::tube(MAX_GENERATED_VERTICES, 2, 0.0, 1.0, |_| 0.1).unwrap_err()
    ));
    let huge = BeamParams {
        cells: [100_000, 100_000, 100_000],
        ..BeamParams::default()
    };
    assert!(too_large(generators::beam(&huge).unwrap_err()));
    let overflow = BeamParams {
        cells: [usize::MAX, 1, 1],
        ..BeamParams::default()
    };
    assert!(too_large(generators::beam(&overflow).unwrap_err()));
    // Sizes within the limit still build.
    assert_eq!(generators::sheet(65, 1.0).unwrap().num_vertices(), 4225);
}

#[test]
fn a_beam_whose_cells_have_no_finite_volume_is_refused_naming_the_size() {
    let params = generators::BeamParams {
        cells: [2, 1, 1],
        size: [1e200, 1e200, 1e200],
    };
    let e = generators::beam(&params).unwrap_err();
    assert!(
        matches!(&e, Error::InvalidParameter(m) if m.contains("no finite, non-zero volume")),
        "{e}"
    );
    // A tetrahedron's volume problem is named: inverted, non-finite, zero or degenerate.
    let degenerate = Error::BadTetVolume { tet: 3, volume: 2e-2 }.to_string();
    assert!(
        degenerate.contains("degenerate") && !degenerate.contains("zero volume"),
        "{degenerate}"
    );
    assert!(
        Error::BadTetVolume { tet: 0, volume: -1.0 }
            .to_string()
            .contains("inverted")
    );
    assert!(
        Error::BadTetVolume {
            tet: 0,
            volume: f64::INFINITY
        }
        .to_string()
        .contains("not a finite")
    );
    assert!(
        Error::BadTetVolume { tet: 0, volume: 0.0 }
            .to_string()
            .contains("zero volume")
    );
}

#[test]
fn every_surface_format_weft_writes_reads_back_exactly() {
    // A curved, irregular surface: every coordinate a full-precision f64.
    let mut rng = TestRng::new(5);
    let sheet = generators::sheet(6, 0.7).unwrap();
    let moved: Vec<Vector3<f64>> = sheet
        .positions()
        .iter()
        .map(|p| {
            p + Vector3::new(
                rng.uniform(-0.01, 0.01),
                rng.uniform(-0.01, 0.01),
                rng.uniform(-0.2, 0.2),
            )
        })
        .collect();
    let m = sheet.with_positions(moved).unwrap();
    for ext in ["obj", "ply", "vtk"] {
        let path = tmp(&format!("round-trip.{ext}"));
        write_surface(&path, &m).unwrap();
        match read_mesh(&path) {
            Ok(AnyMesh::Surface(back)) => assert_eq!(back, m, ".{ext}"),
            other => panic!(".{ext}: expected a surface, got {other:?}"),
        }
    }
    // A coloured PLY (the error maps weft writes) reads back as the same surface.
    let colored = tmp("colored.ply");
    write_ply(
        &colored,
        m.positions(),
        m.faces(),
        Some(&vec![[1, 2, 3]; m.num_vertices()]),
    )
    .unwrap();
    assert_eq!(read_ply(&colored).unwrap(), m);
}

#[test]
fn ply_reader_takes_other_writers_files_and_names_bad_ones() {
    let path = Path::new("in-memory.ply");
    // Float properties in another order, an extra property, a quad, a trailing element.
    let quad = "ply\nformat ascii 1.0\ncomment from elsewhere\nelement vertex 4\nproperty float z\n\
                property float x\nproperty float y\nproperty float confidence\n\
                element face 1\nproperty list uchar int vertex_index\nelement edge 0\nproperty int vertex1\n\
                end_header\n0 0 0 1\n0 1 0 1\n0 1 1 1\n0 0 1 1\n4 0 1 2 3\n";
    let m = parse_ply(quad, path).unwrap();
    assert_eq!(m.faces(), &[[0, 1, 2], [0, 2, 3]]);
    assert_eq!(m.positions()[2], Vector3::new(1.0, 1.0, 0.0));
    // Faces with texture coordinates before their indices and a colour after them.
    let textured = quad.replace(
        "element face 1\nproperty list uchar int vertex_index\n",
        "element face 1\nproperty list uchar float texcoord\nproperty list uchar int vertex_index\nproperty uchar red\n",
    );
    let textured = textured.replace("4 0 1 2 3\n", "8 0 0 1 0 1 1 0 1 4 0 1 2 3 255\n");
    assert_eq!(parse_ply(&textured, path).unwrap(), m);
    let short = textured.replace("4 0 1 2 3 255\n", "4 0 1 2 3\n");
    let e = parse_ply(&short, path).unwrap_err();
    assert!(e.to_string().contains("fewer than its properties declare"), "{e}");
    let long = textured.replace("4 0 1 2 3 255\n", "4 0 1 2 3 255 7\n");
    let e = parse_ply(&long, path).unwrap_err();
    assert!(e.to_string().contains("more than its properties declare"), "{e}");
    let bad = |text: &str, expected: &str| {
        let e = parse_ply(text, path).unwrap_err();
        assert!(matches!(e, Error::Parse { .. }), "{e}");
        assert!(e.to_string().contains(expected), "{e} should say {expected:?}");
    };
    let header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\n\
                  element face 1\nproperty list uchar int vertex_indices\nend_header\n";
    bad(&format!("{header}0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"), "face index \"3\"");
    bad(&format!("{header}0 0 0\n1 0 0\n0 1 0\n2 0 1\n"), "at least 3");
    bad(&format!("{header}0 0 0\n1 0\n0 1 0\n3 0 1 2\n"), "vertex has 2 values");
    bad(
        &format!("{header}0 0 0\n1 0 0\n0 1 0\n"),
        "file ends inside element face",
    );
    bad(&format!("{header}0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n"), "bad coordinate");
    bad(
        &header.replace("element vertex 3", "element vertex 3000000000"),
        "declares 3000000000 rows",
    );
    bad(&header.replace("ascii", "binary_little_endian"), "binary_little_endian");
    let body = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    bad(
        &format!("{}{body}", header.replace("property double z\n", "")),
        "no x, y and z",
    );
    bad(&header.replace("end_header\n", ""), "end_header");
    bad("solid stl\n", "not a PLY file");
}

#[test]
fn vtk_reader_takes_triangles_where_there_are_no_tetrahedra() {
    let path = tmp("surface.vtk");
    write_vtk_triangles(
        &path,
        square().positions(),
        square().faces(),
        &[("height", 1, &[0.0; 4])],
    )
    .unwrap();
    match read_vtk(&path).unwrap() {
        AnyMesh::Surface(m) => assert_eq!(m, square()),
        other => panic!("expected a surface, got {other:?}"),
    }
    // A file of lines only (cell type 3) is neither.
    let lines = "# vtk DataFile Version 3.0\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 2 double\n0 0 0\n1 0 0\n\
                 CELLS 1 3\n2 0 1\nCELL_TYPES 1\n3\n";
    let e = parse_vtk(lines, Path::new("lines.vtk")).unwrap_err();
    assert!(e.to_string().contains("or triangles"), "{e}");
    // A triangle cell with four indices is named on its line.
    let bad = lines.replace(
        "CELLS 1 3\n2 0 1\nCELL_TYPES 1\n3\n",
        "CELLS 1 5\n4 0 1 0 1\nCELL_TYPES 1\n5\n",
    );
    let e = parse_vtk(&bad, Path::new("bad.vtk")).unwrap_err();
    assert!(e.to_string().contains("triangle with 4 indices"), "{e}");
}
