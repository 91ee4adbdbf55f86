//! What a guarded roll-out asks of a surrogate, and the trivial one.

use crate::integrators::ImplicitEuler;

/// A surrogate's own failure, boxed so that a model in a crate above weft-sim (weft-nn's
/// candle errors) can return it unchanged; the guard wraps it in
/// [`crate::Error::Surrogate`] with the surrogate's name.
pub type SurrogateError = Box<dyn std::error::Error + Send + Sync>;

/// What a surrogate sees when asked for frame `frame`: the last two **accepted** frames
/// (so `current − previous` is `Δt` times the velocity) and the step's controls.
#[derive(Debug, Clone, Copy)]
pub struct StepInput<'a> {
    /// Index of the frame to propose (the first step of a roll-out is frame 1).
    pub frame: usize,
    /// Time step (s).
    pub dt: f64,
    /// `p_{m−1}`: the last accepted frame, flat positions (m).
    pub current: &'a [f64],
    /// `p_{m−2}`: the frame before it (m); equal to `current` at rest.
    pub previous: &'a [f64],
    /// The step's controls `q_m`: prescribed DOFs `(dof, value)` (m), the grasp.
    pub prescribed: &'a [(usize, f64)],
}

/// Anything that proposes the next frame of an implicit-Euler scene from the accepted
/// history and the controls (docs/GUARD.md).
///
/// The guard checks every proposal against the step's physics, so a surrogate need not be
/// accurate to be safe — only accurate to be *fast*: the fewer proposals the guard
/// corrects, the fewer Newton solves. The learned models of weft-nn (the embedding's latent
/// simulator, NNWarp, the limb models, the drape network) implement this trait in weft-nn:
/// they decode their prediction to flat positions, return their candle errors as
/// [`SurrogateError`], and, where they carry a latent state, re-encode it from the frame
/// passed to [`Surrogate::observe`], since a corrected frame is not the one they predicted.
pub trait Surrogate: Send + std::fmt::Debug {
    /// Short name for reports and errors (`"inertial"`, a model directory's name, …).
    fn name(&self) -> &str;
    /// The DOF count (3 per vertex) of the mesh the surrogate was built for; the guard
    /// refuses a surrogate for another mesh.
    fn num_dofs(&self) -> usize;
    /// The scene the surrogate was trained on, if it is tied to one; the guard refuses it
    /// on another scene.
    fn scene(&self) -> Option<&str> {
        None
    }
    /// The time step (s) the surrogate was trained at, if it is tied to one; the guard
    /// refuses it on a scene stepped at another.
    fn dt(&self) -> Option<f64> {
        None
    }
    /// The proposed frame `p_m` (flat positions, m; `num_dofs` entries). Its prescribed
    /// DOFs may be left anywhere: the guard sets them to the controls.
    fn propose(&mut self, input: &StepInput<'_>) -> Result<Vec<f64>, SurrogateError>;
    /// The frame the guard passed on for the frame just proposed (`corrected`: not the
    /// proposal but a Newton solve's). Surrogates without state ignore it.
    fn observe(&mut self, _accepted: &[f64], _corrected: bool) {}
}

/// The inertial predictor `x + Δt v = 2p_{m−1} − p_{m−2}` with the prescribed DOFs at
/// their controls: the implicit-Euler solver's own start, and the bar any learned
/// surrogate has to beat (its one-step error is the step's `Δt² a`).
#[derive(Debug, Clone)]
pub struct InertialPredictor {
    num_dofs: usize,
}

impl InertialPredictor {
    /// A predictor for meshes of `num_dofs` DOFs.
    pub fn new(num_dofs: usize) -> Self {
        Self { num_dofs }
    }

    /// A predictor for `integrator`'s mesh.
    pub fn for_integrator(integrator: &ImplicitEuler) -> Self {
        Self::new(integrator.positions().len())
    }
}

impl Surrogate for InertialPredictor {
    fn name(&self) -> &str {
        "inertial"
    }
    fn num_dofs(&self) -> usize {
        self.num_dofs
    }
    fn propose(&mut self, input: &StepInput<'_>) -> Result<Vec<f64>, SurrogateError> {
        let mut x: Vec<f64> = input
            .current
            .iter()
            .zip(input.previous)
            .map(|(c, p)| 2.0 * c - p)
            .collect();
        for &(dof, value) in input.prescribed {
            x[dof] = value;
        }
        Ok(x)
    }
}
