//! The legacy-VTK readers must return a mesh or a typed error for any bytes.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let _ = weft_mesh::io::parse_vtk_tets(&text, std::path::Path::new("fuzz.vtk"));
    let _ = weft_mesh::io::parse_vtk(&text, std::path::Path::new("fuzz.vtk"));
});
