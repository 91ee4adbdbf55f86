//! Cross-crate tests live in `tests/tests/integration/` (one binary); this library is empty by design.
