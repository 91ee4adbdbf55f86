//! Energy terms. Each file is one physical model; all implement [`crate::Energy`].

mod dual;
mod external;
mod fem_cloth;
mod obstacle;
mod springs;

pub use external::{ConstantForce, Inertia, ZeroLengthSprings};
pub use fem_cloth::{DihedralBending, Membrane};
pub use obstacle::{ObstaclePenalty, ObstacleShape};
pub use springs::Springs;
