//! The seeded pseudo-random generator every simulation draws from: SplitMix64, defined
//! in weft-linalg (the lowest crate weft-sim and weft-testkit share) and re-exported here,
//! so scene motion, jitter, perturbations and dataset seeds keep their one source.

pub use weft_linalg::SplitMix64;
