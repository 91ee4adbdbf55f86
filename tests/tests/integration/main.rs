//! weft's cross-crate tests as one binary (one link in CI, the house style): pipelines
//! across crates, scenes read from `fixtures/`, the ground-truth regression, the readers'
//! property tests, and the layer order of the crates themselves.

mod fixtures;
mod ground_truth_regression;
mod layers;
mod pipeline;
mod quoted_figures;
mod readers;
