//! xtask's command line end to end, as one test binary (one link for the crate): each
//! module drives the built `xtask` binary through one command family.

mod acap;
mod dataset;
mod diagnostics;
mod embed_diagnostics;
mod newcomer;
mod pipes;
mod report;
mod score;
mod train;
