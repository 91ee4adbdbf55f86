//! Time integrators and static solves, each built on the one [`crate::NewtonSolver`] or
//! on a pre-factorised linear system:
//!
//! - [`implicit_euler`]: implicit Euler in variational form (Tan et al. Eq. 4), the
//!   cloth and soft-tissue integrator;
//! - [`newmark`]: Newmark-β (average acceleration) for tetrahedral FEM;
//! - [`quasistatic`]: static equilibrium under loads, by load stepping;
//! - [`prefactorized`]: linear elasticity with its constant stiffness factorised once
//!   (the NNWarp baseline), dynamic or static.

pub mod implicit_euler;
pub mod newmark;
pub mod prefactorized;
pub mod quasistatic;

pub use implicit_euler::{ForceResidual, ImplicitEuler, StepReport};
pub use newmark::{Newmark, NewmarkReport};
pub use prefactorized::{LinearSolve, LinearStepReport, PrefactorizedLinear, RayleighDamping};
pub use quasistatic::{Quasistatic, QuasistaticReport};
