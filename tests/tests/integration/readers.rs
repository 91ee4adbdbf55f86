//! Every mesh and scene reader returns a typed error — never a panic, a hang or a huge
//! allocation from a lying header — for random and mutated input (property tests; the
//! cargo-fuzz targets in `fuzz/` run the same readers for long; see docs/FUZZING.md).
//! `PROPTEST_CASES=100000 cargo test --release -p weft-integration --test integration readers` runs
//! a long session.

use std::path::Path;

use proptest::prelude::*;
use weft_mesh::io::{parse_obj, parse_ply, parse_tetgen, parse_vtk, parse_vtk_tets};
use weft_sim::AnyScene;

/// The reference files, written once (tests run in parallel).
fn fixtures() -> &'static (String, String, String, String) {
    static TEXTS: std::sync::OnceLock<(String, String, String, String)> = std::sync::OnceLock::new();
    TEXTS.get_or_init(|| {
        let (node, ele) = write_tetgen_and_vtk();
        let dir = std::env::temp_dir().join(format!("weft-readers-{}", std::process::id()));
        (
            write_obj_text(),
            node,
            ele,
            std::fs::read_to_string(dir.join("b.vtk")).unwrap(),
        )
    })
}

fn obj_text() -> String {
    fixtures().0.clone()
}

fn tetgen_texts() -> (String, String) {
    (fixtures().1.clone(), fixtures().2.clone())
}

fn vtk_text() -> String {
    fixtures().3.clone()
}

fn write_obj_text() -> String {
    let m = weft_mesh::generators::sheet(4, 1.0).unwrap();
    let dir = std::env::temp_dir().join(format!("weft-readers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("s.obj");
    weft_mesh::io::write_obj(&path, m.positions(), m.faces()).unwrap();
    std::fs::read_to_string(path).unwrap()
}

/// The sheet of [`write_obj_text`] as a PLY, with per-vertex colours (as weft's error maps).
fn ply_text() -> String {
    static TEXT: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    TEXT.get_or_init(|| {
        let m = weft_mesh::generators::sheet(4, 1.0).unwrap();
        let dir = std::env::temp_dir().join(format!("weft-readers-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.ply");
        let colors = vec![[10, 20, 30]; m.num_vertices()];
        weft_mesh::io::write_ply(&path, m.positions(), m.faces(), Some(&colors)).unwrap();
        std::fs::read_to_string(path).unwrap()
    })
    .clone()
}

fn write_tetgen_and_vtk() -> (String, String) {
    let m = weft_mesh::generators::beam(&weft_mesh::generators::BeamParams {
        cells: [2, 1, 1],
        size: [0.2, 0.1, 0.1],
    })
    .unwrap();
    let dir = std::env::temp_dir().join(format!("weft-readers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    weft_mesh::io::write_tetgen(&dir.join("b.node"), &m).unwrap();
    weft_mesh::io::write_vtk_tets(&dir.join("b.vtk"), m.positions(), m.tets(), &[]).unwrap();
    (
        std::fs::read_to_string(dir.join("b.node")).unwrap(),
        std::fs::read_to_string(dir.join("b.ele")).unwrap(),
    )
}

fn scene_text() -> String {
    weft_sim::load("sheet-fem-obstacle", true)
        .unwrap()
        .scene
        .to_toml()
        .unwrap()
}

/// Edits that exercise parsers: tokens that overflow, NaN, negative and huge counts.
const NASTY: [&str; 12] = [
    "-9223372036854775808",
    "18446744073709551616",
    "1e999",
    "nan",
    "-1",
    "0",
    "99999999999999",
    "\n",
    "#",
    "/",
    "f 1 2",
    "v 1 2",
];

/// A mutation: (position fraction, kind, payload index).
fn mutate(text: &str, edits: &[(f64, u8, usize)]) -> String {
    let mut bytes = text.as_bytes().to_vec();
    for &(at, kind, k) in edits {
        let i = ((at * bytes.len() as f64) as usize).min(bytes.len());
        match kind % 4 {
            0 if i < bytes.len() => {
                bytes.remove(i);
            }
            1 => bytes.splice(i..i, NASTY[k % NASTY.len()].bytes()).for_each(drop),
            2 if i < bytes.len() => bytes[i] = bytes[i].wrapping_add(1 + k as u8),
            _ => bytes.truncate(i),
        }
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

fn edits() -> impl Strategy<Value = Vec<(f64, u8, usize)>> {
    prop::collection::vec((0.0f64..1.0, any::<u8>(), any::<usize>()), 1..6)
}

proptest! {
    #[test]
    fn obj_reader_never_panics(text in "\\PC{0,400}", e in edits()) {
        let _ = parse_obj(&text, Path::new("random.obj"));
        let _ = parse_obj(&mutate(&obj_text(), &e), Path::new("mutated.obj"));
    }

    #[test]
    fn tetgen_reader_never_panics(a in "\\PC{0,200}", b in "\\PC{0,200}", e in edits(), f in edits()) {
        let (node, ele) = tetgen_texts();
        let _ = parse_tetgen(&a, &b, Path::new("r.node"), Path::new("r.ele"));
        let _ = parse_tetgen(&mutate(&node, &e), &mutate(&ele, &f), Path::new("m.node"), Path::new("m.ele"));
    }

    #[test]
    fn vtk_reader_never_panics(text in "\\PC{0,400}", e in edits()) {
        let _ = parse_vtk_tets(&text, Path::new("random.vtk"));
        let _ = parse_vtk_tets(&format!("UNSTRUCTURED_GRID {text}"), Path::new("random.vtk"));
        let _ = parse_vtk_tets(&mutate(&vtk_text(), &e), Path::new("mutated.vtk"));
        let _ = parse_vtk(&format!("UNSTRUCTURED_GRID {text}"), Path::new("random.vtk"));
        let _ = parse_vtk(&mutate(&vtk_text(), &e), Path::new("mutated.vtk"));
    }

    #[test]
    fn ply_reader_never_panics(text in "\\PC{0,400}", e in edits()) {
        let _ = parse_ply(&text, Path::new("random.ply"));
        let _ = parse_ply(&format!("ply\nformat ascii 1.0\n{text}"), Path::new("random.ply"));
        let _ = parse_ply(&mutate(&ply_text(), &e), Path::new("mutated.ply"));
    }

    #[test]
    fn scene_reader_never_panics_and_round_trips_what_it_accepts(text in "\\PC{0,300}", e in edits()) {
        let _ = AnyScene::from_toml(&text);
        if let Ok(scene) = AnyScene::from_toml(&mutate(&scene_text(), &e)) {
            let again = AnyScene::from_toml(&scene.to_toml().unwrap()).unwrap();
            prop_assert_eq!(again, scene);
        }
    }
}

#[test]
fn unmutated_files_read_back_exactly() {
    let m = weft_mesh::generators::sheet(4, 1.0).unwrap();
    let back = parse_obj(&obj_text(), Path::new("s.obj")).unwrap();
    assert_eq!(back.positions(), m.positions());
    let (node, ele) = tetgen_texts();
    let t = parse_tetgen(&node, &ele, Path::new("b.node"), Path::new("b.ele")).unwrap();
    let v = parse_vtk_tets(&vtk_text(), Path::new("b.vtk")).unwrap();
    assert_eq!(t.tets(), v.tets());
    let p = parse_ply(&ply_text(), Path::new("s.ply")).unwrap();
    assert_eq!(p, m);
    assert_eq!(AnyScene::from_toml(&scene_text()).unwrap().name(), "sheet-fem-obstacle");
}

#[test]
fn lying_header_counts_allocate_nothing_and_are_typed_errors() {
    // Regression: the TetGen and VTK readers reserved capacity for the count in the
    // header before reading a single point, so `999999999999999 3 0 0` aborted the process
    // on allocation.
    let node = "999999999999999 3 0 0\n0 0 0 0\n";
    let e = parse_tetgen(node, "1 4 0\n0 0 0 0 0\n", Path::new("l.node"), Path::new("l.ele"));
    assert!(
        e.unwrap_err()
            .to_string()
            .contains("file ends after 1 of 999999999999999 points")
    );
    let (node, _) = tetgen_texts();
    let ele = "999999999999999 4 0\n0 0 1 2 3\n";
    assert!(parse_tetgen(&node, ele, Path::new("l.node"), Path::new("l.ele")).is_err());
    let vtk = "# vtk DataFile Version 3.0\nx\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 999999999999999 double\n0 0 0\n";
    assert!(parse_vtk_tets(vtk, Path::new("l.vtk")).is_err());
    let vtk = "DATASET UNSTRUCTURED_GRID\nPOINTS 1 double\n0 0 0\nCELLS 999999999999999 5\n4 0 0 0 0\n";
    assert!(parse_vtk_tets(vtk, Path::new("l.vtk")).is_err());
    // A cell size of usize::MAX must not overflow the cursor.
    let vtk = "DATASET UNSTRUCTURED_GRID\nPOINTS 1 double\n0 0 0\nCELLS 2 5\n18446744073709551615 0\n";
    assert!(parse_vtk_tets(vtk, Path::new("l.vtk")).is_err());
    let ply = "ply\nformat ascii 1.0\nelement vertex 999999999999999\nproperty float x\nproperty float y\n\
               property float z\nend_header\n0 0 0\n";
    let e = parse_ply(ply, Path::new("l.ply")).unwrap_err();
    assert!(e.to_string().contains("declares 999999999999999 rows"), "{e}");
}
