//! The TetGen reader must return a mesh or a typed error for any pair of files (the
//! input is split at its first NUL byte into `.node` and `.ele` text).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let split = data.iter().position(|&b| b == 0).unwrap_or(data.len());
    let node = String::from_utf8_lossy(&data[..split]);
    let ele = String::from_utf8_lossy(data.get(split + 1..).unwrap_or(&[]));
    let _ = weft_mesh::io::parse_tetgen(&node, &ele, "fuzz.node".as_ref(), "fuzz.ele".as_ref());
});
