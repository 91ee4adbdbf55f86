//! Tan et al.'s latent simulator as a surrogate of weft-sim's guard (docs/GUARD.md, issue
//! 73): one step from two accepted frames, `p_m = ACAP⁻¹ ∘ D(MLP(E(p_{m−2}), E(p_{m−1}),
//! q_m))` (§V-B, Eq. 7), decoded as [`super::LatentRollout::step`] decodes.
//!
//! The surrogate keeps no latent state: every proposal re-encodes the two frames the guard
//! passed on, so a corrected frame is what the next step starts from, and the latent
//! roll-out's drift (docs/EMBEDDING.md) cannot build up under the guard. Its one-step
//! error is bounded below by the autoencoder's reconstruction error, which is why it is
//! about ten times the inertial predictor's on `sheet-ms` (docs/GUARD.md).

use std::path::Path;
use std::sync::Arc;

use candle_core::Device;
use weft_acap::{AcapFeatures, Feature, FeatureNormalization, PoissonPseudoInverse};
use weft_data::ClothDataset;
use weft_sim::guard::{StepInput, Surrogate, SurrogateError};

use super::runtime::{FrameProfile, decode_profiled};
use super::training::{EmbedData, EmbedModel, sequence_features};
use crate::convert;
use crate::error::{Error, Result};

/// A trained embedding (autoencoder and latent simulator) with what it needs to encode
/// frames given as positions and to decode its prediction: the rest mesh's ACAP extractor,
/// the feature normalisation it was trained with, and the Poisson pseudo-inverse pinned at
/// the dataset's grasp. Cheap to clone (the networks are shared).
#[derive(Debug, Clone)]
pub struct EmbedSurrogate {
    model: Arc<EmbedModel>,
    acap: Arc<AcapFeatures>,
    inverse: Arc<PoissonPseudoInverse>,
    normalization: FeatureNormalization,
    scene: String,
    dt: f64,
}

impl EmbedSurrogate {
    /// The surrogate of `model`, trained on `data` (or loaded for it: [`EmbedModel::load`]).
    pub fn new(model: Arc<EmbedModel>, data: &EmbedData) -> Self {
        Self {
            model,
            acap: data.acap.clone(),
            inverse: data.inverse.clone(),
            normalization: data.normalization.clone(),
            scene: data.dataset.scene.name.clone(),
            dt: data.dataset.scene.dt,
        }
    }

    /// The surrogate of the model directory `dir` (`cargo xtask train embed`, or the embed
    /// experiment's), after its last stage, on `dataset` (the one it was trained on: its rest
    /// mesh, grasp and scene), with the model's own normalisation (`normalization.json`).
    pub fn load(dir: &Path, dataset: ClothDataset) -> Result<Self> {
        let normalization: FeatureNormalization = crate::checkpoint::read_json(&dir.join("normalization.json"))?;
        let data = EmbedData::with_normalization(dataset, normalization)?;
        let model = EmbedModel::load(dir, &data, 3)?;
        Ok(Self::new(Arc::new(model), &data))
    }

    /// The trained networks.
    pub fn model(&self) -> &EmbedModel {
        &self.model
    }

    /// The grasped vertices, in the order of the controls `q` ([`EmbedSurrogate::predict`]).
    pub fn grasp(&self) -> &[usize] {
        self.inverse.pins()
    }

    /// Frame `p_m` (flat positions, m) from `p_{m−2}`, `p_{m−1}` and the controls `q_m` (3
    /// per grasped vertex, in [`EmbedSurrogate::grasp`]'s order): the two frames encoded as
    /// a sequence and normalised as the training frames were, one latent step, decoded
    /// pinned at `q_m`.
    pub fn predict(&self, previous: &[f64], current: &[f64], q: &[f64]) -> Result<Vec<f64>> {
        let n = 3 * self.inverse.num_vertices();
        if previous.len() != n || current.len() != n {
            return Err(Error::Shape {
                what: "embed surrogate input",
                expected: format!("two frames of {n} DOFs"),
                got: format!("{} and {}", previous.len(), current.len()),
            });
        }
        let features: Vec<Vec<Feature>> = sequence_features(&self.acap, &[previous, current])?
            .iter()
            .map(|f| self.normalization.normalize_all(f))
            .collect();
        let codes = self.model.codes_of_features(&features)?;
        let latent = self.model.config.autoencoder.latent;
        let code = |z: &[f64]| convert::f64_to_tensor("latent code", z, &[1, latent], &Device::Cpu);
        let qt = convert::f64_to_tensor("roll-out controls", q, &[1, q.len()], &Device::Cpu)?;
        let z = self.model.simulator.step(&code(&codes[0])?, &code(&codes[1])?, &qt)?;
        decode_profiled(
            &self.model.autoencoder,
            &self.inverse,
            &self.normalization,
            &z,
            q,
            &mut FrameProfile::default(),
        )
    }

    /// The controls `q_m` of a step, in the grasp's order, from its prescribed DOFs; every
    /// grasped DOF must be prescribed (the latent simulator was trained on all of them).
    pub fn controls(&self, prescribed: &[(usize, f64)]) -> Result<Vec<f64>> {
        let grasp = self.grasp();
        let mut q = vec![f64::NAN; 3 * grasp.len()];
        for &(dof, value) in prescribed {
            if let Some(g) = grasp.iter().position(|&v| v == dof / 3) {
                q[3 * g + dof % 3] = value;
            }
        }
        match q.iter().position(|v| v.is_nan()) {
            Some(i) => Err(Error::InvalidParameter {
                name: "controls",
                value: format!("grasped vertex {} has no prescribed DOF {}", grasp[i / 3], i % 3),
                reason: "the latent simulator steps with every grasped DOF prescribed",
            }),
            None => Ok(q),
        }
    }
}

impl Surrogate for EmbedSurrogate {
    fn name(&self) -> &str {
        "embed"
    }
    fn num_dofs(&self) -> usize {
        3 * self.inverse.num_vertices()
    }
    fn scene(&self) -> Option<&str> {
        Some(&self.scene)
    }
    fn dt(&self) -> Option<f64> {
        Some(self.dt)
    }
    fn propose(&mut self, input: &StepInput<'_>) -> std::result::Result<Vec<f64>, SurrogateError> {
        let q = self.controls(input.prescribed)?;
        Ok(self.predict(input.previous, input.current, &q)?)
    }
}
