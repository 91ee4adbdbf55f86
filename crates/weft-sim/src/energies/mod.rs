//! Energy terms. Each file is one physical model; all implement [`crate::Energy`].

mod body_forces;
mod external;
mod springs;
mod tet_fem;

pub use body_forces::hemisphere_direction;
pub use external::{ConstantForce, Inertia, ZeroLengthSprings};
pub use springs::Springs;
pub use tet_fem::{LameParameters, Material, TetElasticity, NEO_HOOKEAN_J_MIN};
