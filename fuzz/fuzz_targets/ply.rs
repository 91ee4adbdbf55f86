//! The ASCII PLY reader must return a mesh or a typed error for any bytes.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let _ = weft_mesh::io::parse_ply(&text, std::path::Path::new("fuzz.ply"));
});
