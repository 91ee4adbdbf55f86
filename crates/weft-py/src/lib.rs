//! `weft._native`: the Rust half of the `weft` Python package (built by maturin from
//! `pyproject.toml`; the Python half is `python/weft/`).
//!
//! What it is: thin bindings over the library crates on numpy arrays — weft-proj's two
//! projection layers with their hand-written backward passes and per-example warm
//! starts ([`proj`]), mesh generators and files ([`mesh`]), scene simulation through
//! weft-data's recorder ([`sim`]), ACAP features and their Poisson inverse ([`acap`]),
//! and any weft dataset read with its checksums verified ([`data`]). Solves run with the
//! GIL released.
//!
//! What it is not: a second implementation of anything. Every number comes from the
//! crate that owns the math; this crate converts arrays, checks their shapes and turns
//! the crates' typed errors into Python exceptions ([`errors`]). The PyTorch autograd
//! functions are Python (`weft/torch.py`) over [`proj`]'s forward and backward calls.
//!
//! Arrays: positions are float64 `[V, 3]` or `[B, V, 3]` in metres (C order; the Python
//! wrappers convert), faces int64 `[F, 3]`.

mod acap;
mod arrays;
mod data;
mod errors;
mod mesh;
mod proj;
mod sim;

use pyo3::prelude::*;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SolverError", m.py().get_type::<errors::SolverError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    proj::register(m)?;
    mesh::register(m)?;
    sim::register(m)?;
    acap::register(m)?;
    data::register(m)?;
    Ok(())
}
