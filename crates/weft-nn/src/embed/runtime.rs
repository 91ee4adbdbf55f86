//! Latent roll-out simulation (Tan et al. §V-B): from two codes and a control sequence,
//! the latent simulator predicts each next code and `ACAP⁻¹ ∘ D` decodes it to vertex
//! positions, pinned at the frame's grasped positions. No ground-truth solve is involved,
//! which is where the speed comes from.

use std::sync::Arc;
use std::time::{Duration, Instant};

use candle_core::{Device, Tensor};
use nalgebra::Vector3;
use weft_acap::{Feature, FeatureNormalization, PoissonPseudoInverse};

use super::model::{LatentSimulator, MeshAutoencoder};
use crate::convert;
use crate::error::{Error, Result};

/// Where one roll-out frame's time went.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameProfile {
    /// The latent simulator's step (`MLP`).
    pub latent_step: Duration,
    /// The decoder's layers (`D`), to normalised features.
    pub decoder: Duration,
    /// Of which each layer: the fully connected one, then each graph convolution.
    pub decoder_layers: Vec<Duration>,
    /// Denormalisation, Rodrigues and `T = R S` per vertex (weft-acap).
    pub rotations: Duration,
    /// The pre-factorised Poisson solve for positions (weft-acap).
    pub solve: Duration,
}

/// A running latent simulation.
#[derive(Debug)]
pub struct LatentRollout<'a> {
    autoencoder: &'a MeshAutoencoder,
    simulator: &'a LatentSimulator,
    inverse: Arc<PoissonPseudoInverse>,
    normalization: FeatureNormalization,
    previous: Tensor,
    current: Tensor,
}

impl<'a> LatentRollout<'a> {
    /// Starts from the codes `z1`, `z2` of the two frames before the first predicted one.
    pub fn new(
        autoencoder: &'a MeshAutoencoder,
        simulator: &'a LatentSimulator,
        inverse: Arc<PoissonPseudoInverse>,
        normalization: FeatureNormalization,
        z1: &[f64],
        z2: &[f64],
    ) -> Result<Self> {
        let latent = autoencoder.config().latent;
        let code = |z: &[f64]| convert::f64_to_tensor("latent code", z, &[1, latent], &Device::Cpu);
        Ok(Self {
            autoencoder,
            simulator,
            inverse,
            normalization,
            previous: code(z1)?,
            current: code(z2)?,
        })
    }

    /// Restarts the roll-out from the codes `z1`, `z2`.
    pub fn restart(&mut self, z1: &[f64], z2: &[f64]) -> Result<()> {
        let latent = self.autoencoder.config().latent;
        self.previous = convert::f64_to_tensor("latent code", z1, &[1, latent], &Device::Cpu)?;
        self.current = convert::f64_to_tensor("latent code", z2, &[1, latent], &Device::Cpu)?;
        Ok(())
    }

    /// The next frame's positions (flat, metres) for the grasped positions `q` (3 per
    /// grasped vertex, in the pseudo-inverse's pin order).
    pub fn step(&mut self, q: &[f64]) -> Result<Vec<f64>> {
        Ok(self.step_profiled(q)?.0)
    }

    /// [`LatentRollout::step`] with the time of each stage.
    pub fn step_profiled(&mut self, q: &[f64]) -> Result<(Vec<f64>, FrameProfile)> {
        check_controls(&self.inverse, q)?;
        let mut profile = FrameProfile::default();
        let t = Instant::now();
        let qt = convert::f64_to_tensor("roll-out controls", q, &[1, q.len()], &Device::Cpu)?;
        let z = self.simulator.step(&self.previous, &self.current, &qt)?;
        profile.latent_step = t.elapsed();
        let p = decode_profiled(
            self.autoencoder,
            &self.inverse,
            &self.normalization,
            &z,
            q,
            &mut profile,
        )?;
        self.previous = std::mem::replace(&mut self.current, z);
        Ok((p, profile))
    }
}

/// The controls `q` checked against the pseudo-inverse: 3 values per pin.
fn check_controls(inverse: &PoissonPseudoInverse, q: &[f64]) -> Result<()> {
    let pins = inverse.pins().len();
    if q.len() != 3 * pins {
        return Err(Error::Shape {
            what: "roll-out controls",
            expected: format!("{} values (3 per grasped vertex)", 3 * pins),
            got: format!("{}", q.len()),
        });
    }
    Ok(())
}

/// `ACAP⁻¹ ∘ D` of one code `z` (`[1, latent]`), pinned at the grasped positions `q` (3 per
/// pin, in the pseudo-inverse's pin order): flat positions (m). Fills `profile`'s decoder,
/// rotation and solve times. The one decode of the roll-out ([`LatentRollout`]) and of the
/// guard's surrogate ([`super::EmbedSurrogate`]), so the two cannot drift apart.
pub(super) fn decode_profiled(
    autoencoder: &MeshAutoencoder,
    inverse: &PoissonPseudoInverse,
    normalization: &FeatureNormalization,
    z: &Tensor,
    q: &[f64],
    profile: &mut FrameProfile,
) -> Result<Vec<f64>> {
    check_controls(inverse, q)?;
    let t = Instant::now();
    let (y, layers) = autoencoder.decode_timed(z)?;
    let flat: Vec<f32> = y.flatten_all()?.to_vec1()?;
    profile.decoder = t.elapsed();
    profile.decoder_layers = layers;
    let t = Instant::now();
    let normalised = convert::f32_to_f64("decoded features", &flat)?;
    let features: Vec<Feature> = normalised
        .chunks_exact(9)
        .map(|f| normalization.denormalize(&std::array::from_fn(|d| f[d])))
        .collect();
    let gradients = inverse.deformation_gradients(&features)?;
    profile.rotations = t.elapsed();
    let t = Instant::now();
    let pin_positions: Vec<Vector3<f64>> = q.chunks_exact(3).map(|c| Vector3::new(c[0], c[1], c[2])).collect();
    let p = inverse.positions_from_gradients(&gradients, &pin_positions)?;
    profile.solve = t.elapsed();
    Ok(p.iter().flat_map(|v| [v.x, v.y, v.z]).collect())
}
