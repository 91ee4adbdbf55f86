//! weft-sim's integration tests as one binary (one link in CI, the house style): each
//! module is one area of the simulator, tested through the public API only.

mod drape;
mod energies;
mod fem;
mod guard;
mod guard_limb;
mod guard_quasistatic;
mod simulation;
mod volume_scenes;
mod warp;
