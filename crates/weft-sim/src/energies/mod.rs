//! Energy terms. Each file is one physical model; all implement [`crate::Energy`].

mod body_forces;
mod dual;
mod external;
mod fem_cloth;
mod obstacle;
mod springs;
mod tet_fem;

pub use body_forces::hemisphere_direction;
pub use external::{ConstantForce, Inertia, ZeroLengthSprings};
pub use fem_cloth::{DihedralBending, Membrane};
pub use obstacle::{ObstaclePenalty, ObstacleShape};
pub use springs::Springs;
pub use tet_fem::{LameParameters, Material, NEO_HOOKEAN_J_MIN, TetElasticity};
