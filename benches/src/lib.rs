//! Cross-crate benchmarks for weft: see `README.md` beside this crate; the benches are under `benches/`.
