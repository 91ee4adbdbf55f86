//! Cloth inverse kinematics in the latent space (Tan et al. §V-A): given new positions of
//! the grasped vertices, find the code `z* = argmin_z (P_s + P_b)(ACAP⁻¹(D(z)))`, the
//! grasped vertices pinned by ACAP⁻¹. The application is stateless, so only the elastic
//! potential of L_phys remains (no inertia, no gravity).
//!
//! [`full_space_ik`] minimises the same potential over every vertex with weft-sim's Newton
//! solver, from the same start: the reference the latent answer is compared with.

use std::sync::Arc;
use std::time::Instant;

use candle_core::Tensor;
use nalgebra::Vector3;

use crate::adam::{Adam, AdamSettings};
use crate::embed::{EmbedData, EmbedModel};
use crate::error::{Error, Result};
use crate::ops::{AcapInverse, ClothPotential};
use crate::params::{Init, ParamStore};

/// How the latent minimisation runs: Adam on `z` (invariant to the energy's scale, which
/// spans orders of magnitude between scenes), keeping the best code seen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkSettings {
    pub iterations: usize,
    pub learning_rate: f64,
}

impl Default for IkSettings {
    fn default() -> Self {
        Self {
            iterations: 200,
            learning_rate: 0.02,
        }
    }
}

/// The outcome of one inverse-kinematics solve.
#[derive(Debug, Clone, PartialEq)]
pub struct IkResult {
    /// Positions (flat, metres) at the lowest energy reached.
    pub positions: Vec<f64>,
    /// `P_s + P_b` at the start and at the end (J).
    pub start_energy: f64,
    pub energy: f64,
    pub iterations: usize,
    /// Wall time of the minimisation (s), without the start's set-up.
    pub seconds: f64,
}

fn flat_positions(p: &Tensor) -> Result<Vec<f64>> {
    crate::convert::tensor_to_f64("inverse-kinematics positions", p)
}

/// The positions `ACAP⁻¹(D(z))` pinned at `pins` (the start both solvers share).
pub fn decode_pinned(model: &EmbedModel, data: &EmbedData, z: &[f64], pins: &[Vector3<f64>]) -> Result<Vec<f64>> {
    let device = model.autoencoder_params.device();
    let zt = Tensor::from_vec(z.iter().map(|&x| x as f32).collect::<Vec<_>>(), (1, z.len()), device)?;
    let op = AcapInverse::new(data.inverse.clone(), data.normalization.clone(), vec![pins.to_vec()]);
    flat_positions(&op.apply(&model.autoencoder.decode(&zt)?)?)
}

/// Tan et al. §V-A: minimises `P_s + P_b` over the code, from `z0`, with the grasped
/// vertices at `pins` (in the order of the dataset's grasp).
pub fn latent_ik(
    model: &EmbedModel,
    data: &EmbedData,
    z0: &[f64],
    pins: &[Vector3<f64>],
    settings: IkSettings,
) -> Result<IkResult> {
    if z0.len() != model.config.autoencoder.latent || pins.len() != data.dataset.grasp.len() {
        return Err(Error::Shape {
            what: "inverse-kinematics start",
            expected: format!(
                "a {}-D code and {} pins",
                model.config.autoencoder.latent,
                data.dataset.grasp.len()
            ),
            got: format!("a {}-D code and {} pins", z0.len(), pins.len()),
        });
    }
    let device = model.autoencoder_params.device();
    let mut params = ParamStore::new(device, 0);
    params.create("z", &[1, z0.len()], Init::Zeros)?;
    let z = params.vars()["z"].clone();
    z.set(&Tensor::from_vec(
        z0.iter().map(|&x| x as f32).collect::<Vec<_>>(),
        (1, z0.len()),
        device,
    )?)?;
    let mut adam = Adam::new(
        &params,
        AdamSettings {
            learning_rate: settings.learning_rate,
            ..AdamSettings::default()
        },
    )?;
    let decode = AcapInverse::new(data.inverse.clone(), data.normalization.clone(), vec![pins.to_vec()]);
    let potential = ClothPotential::new(data.integrator.clone());
    let start = Instant::now();
    let mut best: Option<(f64, Tensor)> = None;
    let mut start_energy = f64::NAN;
    for it in 0..=settings.iterations {
        let p = decode.apply(&model.autoencoder.decode(z.as_tensor())?)?;
        let e = potential.apply(&p)?.sum_all()?;
        let value = e.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>()?;
        if it == 0 {
            start_energy = value;
        }
        if best.as_ref().is_none_or(|(b, _)| value < *b) {
            best = Some((value, p.detach()));
        }
        if it < settings.iterations {
            adam.step(&params, &e.backward()?)?;
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    let (energy, p) = best.ok_or(Error::InvalidParameter {
        name: "inverse-kinematics iterations",
        value: settings.iterations.to_string(),
        reason: "ran no evaluation",
    })?;
    Ok(IkResult {
        positions: flat_positions(&p)?,
        start_energy,
        energy,
        iterations: settings.iterations,
        seconds,
    })
}

/// The same potential minimised over every vertex by weft-sim's Newton solver from `x0`
/// (whose grasped vertices are already at their pins; they stay fixed), with the
/// integrator's Newton settings (its Hessian strategy and its tolerance, 1e-5 of the
/// heaviest vertex's weight) and up to `max_iterations`. Without gravity the potential
/// has flat directions (bending a sheet isometrically costs almost nothing), so Newton can
/// stall above the tolerance: the result then holds the last iterate and `converged` is
/// false rather than the solve failing.
pub fn full_space_ik(
    integrator: &Arc<weft_sim::ImplicitEuler>,
    x0: &[f64],
    max_iterations: usize,
) -> Result<(IkResult, bool)> {
    let terms: Vec<&dyn weft_sim::Energy> = integrator
        .terms()
        .iter()
        .map(|t| t.as_ref())
        .filter(|t| weft_sim::is_cloth_elastic(*t))
        .collect();
    let start_energy = terms.iter().map(|t| t.value(x0)).sum();
    let start = Instant::now();
    let mut solver = weft_sim::NewtonSolver::new(x0.len(), &terms, integrator.fixed().to_vec())?;
    let mut x = x0.to_vec();
    let settings = weft_sim::NewtonSettings {
        max_iterations,
        ..integrator.settings
    };
    let (iterations, converged) = match solver.minimize(&terms, &mut x, &settings) {
        Ok(report) => (report.iterations, true),
        Err(weft_sim::Error::NotConverged { iterations, .. }) => (iterations, false),
        Err(e) => return Err(e.into()),
    };
    let energy = terms.iter().map(|t| t.value(&x)).sum();
    Ok((
        IkResult {
            positions: x,
            start_energy,
            energy,
            iterations,
            seconds: start.elapsed().as_secs_f64(),
        },
        converged,
    ))
}
