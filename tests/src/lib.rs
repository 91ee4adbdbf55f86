//! Cross-crate pipeline tests live in `tests/tests/`; this library is empty by design.
