//! Energy terms. Each file is one physical model; all implement [`crate::Energy`].

mod external;
mod springs;

pub use external::{ConstantForce, Inertia, ZeroLengthSprings};
pub use springs::Springs;
