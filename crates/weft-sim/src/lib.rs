//! Ground-truth deformable simulation for weft.
//!
//! Everything here is an [`Energy`] with value, gradient and Hessian, minimised by one
//! [`NewtonSolver`] (SPD projection, descent-guaranteeing line search, sparse Cholesky
//! with its symbolic factorisation reused). Integrators are built on top of it: implicit
//! Euler in variational form (Tan et al. Eq. 4). A scene lists the terms it needs and
//! only those are built: no obstacle, no collision code runs.
//!
//! Every scene kind (cloth, volumetric, soft tissue) loads through one [`load`](mod@load) from a
//! built-in name or a TOML file. [`warp`] holds the geometric warps of a linear solution
//! (modal and rotation-strain warping) and NNWarp's per-node inputs. [`guard`] steps a
//! learned [`Surrogate`] under a [`Guard`] that checks every proposed frame against the
//! implicit-Euler step's residual and corrects it with Newton when its certified error
//! estimate exceeds a tolerance (docs/GUARD.md).
//!
//! This crate is not a learning library (it never touches candle); its only file I/O is
//! reading scene files and the meshes they name.
//!
//! Units: SI throughout — metres, kilograms, seconds, newtons, joules.
//!
//! ```
//! use weft_sim::{energies::{Springs, ConstantForce}, Energy, NewtonSolver, NewtonSettings};
//! use nalgebra::Vector3;
//! // One spring of rest length 1 m hanging a 1 kg point under gravity from a fixed point.
//! let rest = [Vector3::zeros(), Vector3::new(0.0, 0.0, -1.0)];
//! let spring = Springs::at_rest("spring", &rest, vec![[0, 1]], 100.0)?;
//! let gravity = ConstantForce::gravity(&[0.0, 1.0], [0.0, 0.0, -9.81])?;
//! let terms: [&dyn Energy; 2] = [&spring, &gravity];
//! let fixed = vec![true, true, true, false, false, false];
//! let mut solver = NewtonSolver::new(6, &terms, fixed)?;
//! let mut x = vec![0.0, 0.0, 0.0, 0.0, 0.0, -1.0];
//! solver.minimize(&terms, &mut x, &NewtonSettings::default())?;
//! assert!((x[5] - (-1.0 - 9.81 / 100.0)).abs() < 1e-9); // Hooke's law
//! # Ok::<(), weft_sim::Error>(())
//! ```

pub mod anchors;
pub mod energies;
pub mod energy;
pub mod error;
pub mod guard;
pub mod integrators;
pub mod newton;
pub mod rng;
pub mod scenes;
pub mod warp;

pub use energy::Energy;
pub use error::{Error, Result};
pub use guard::{
    Correction, ErrorEstimate, Guard, GuardReport, GuardSettings, GuardTolerance, GuardTotals, GuardedFrame,
    InertialPredictor, Outcome, StepInput, Surrogate,
};
pub use integrators::{
    ForceResidual, ImplicitEuler, LinearSolve, LinearStepReport, Newmark, NewmarkReport, PrefactorizedLinear,
    Quasistatic, QuasistaticReport, RayleighDamping, StepReport,
};
pub use newton::{Globalization, HessianProjection, NewtonReport, NewtonSettings, NewtonSolver};
pub use scenes::{
    AnyScene, BUILTIN_SCENES, BUILTIN_VOLUME_SCENES, ClothScene, ClothSimulation, Frame, LoadedScene, MotionLabel,
    SoftTissueScene, VolumeScene, VolumeSimulation, builtin_names, is_cloth_elastic, load,
};
