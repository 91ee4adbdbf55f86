//! weft's cross-crate tests as one binary (one link in CI, the house style): pipelines
//! across crates, scenes read from `fixtures/`, the ground-truth regression, the readers'
//! property tests, the layer order of the crates themselves, and no conflict left by a merge.

mod fixtures;
mod ground_truth_regression;
mod layers;
mod merge_markers;
mod pipeline;
mod quoted_figures;
mod readers;
