//! Scenes: what to simulate, loaded from a built-in name or a TOML file.
//!
//! - [`cloth`]: a triangle mesh (sheet, sheet with holes, ball, OBJ) driven by grasped
//!   vertices, with mass-spring or FEM cloth and optional obstacles ([`ClothScene`]).
//! - [`volume`]: tetrahedral FEM bodies (beams, the limb) under anchors and loads
//!   ([`VolumeScene`]), and the skinned soft-tissue limb ([`SoftTissueScene`]).
//! - [`soft_tissue`]: the limb's skeleton, skinning and soft-tissue dynamics.
//! - [`drape`]: a sleeve draped on the posed limb (Geng et al.'s shirt analogue, design §8).
//! - [`load`](mod@load): one entry point for every kind ([`AnyScene`]).
//!
//! A scene builds only the energy terms it names: a scene without an obstacle runs no
//! collision code.

pub mod cloth;
pub mod drape;
pub mod load;
pub mod soft_tissue;
pub mod volume;

pub use cloth::{BUILTIN_SCENES, ClothScene, ClothSimulation, Frame, MotionLabel, is_cloth_elastic};
pub use load::{AnyScene, LoadedScene, builtin_names, load};
pub use volume::{BUILTIN_VOLUME_SCENES, SoftTissueScene, VolumeScene, VolumeSimulation};
