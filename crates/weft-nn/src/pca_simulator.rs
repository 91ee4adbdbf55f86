//! The latent simulator on a linear subspace: Tan et al.'s MLP (Eq. 7, `MLP(z_{m−2},
//! z_{m−1}, q_m) = z_m`) trained on the codes of a [`PositionPca`] instead of the graph-CNN
//! embedding's — the baseline a user would try first for reduced simulation, so the
//! evaluation shows what the embedding buys over linear algebra for simulation and not only
//! for reconstruction.
//!
//! The PCA basis is orthonormal, so a code distance is a position distance (m). The codes
//! are scaled by one factor, `1/√(mean variance)`, to bring them to order one for the MLP
//! without changing their geometry; the loss is the squared code error (`L_sim`) in those
//! units, on the same training windows as the embedding, and the validation score the same
//! on its validation windows.

use candle_core::{DType, Device, Tensor};

use crate::adam::AdamSettings;
use crate::embed::{EmbedData, FrameRef, LatentSimulator, LatentSimulatorSettings};
use crate::error::{Error, Result};
use crate::params::ParamStore;
use crate::pca::PositionPca;
use crate::trainer::{BatchAt, BatchLoss, Group, Observer, Schedule, Trainable, Trainer, TrainerSettings};

/// How the simulator is trained.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PcaSimulatorSettings {
    pub hidden: Vec<usize>,
    pub adam: AdamSettings,
    pub batch: usize,
    pub epochs: usize,
    pub seed: u64,
    pub schedule: Schedule,
}

impl Default for PcaSimulatorSettings {
    fn default() -> Self {
        Self {
            hidden: vec![256, 256],
            adam: AdamSettings::default(),
            batch: 8,
            epochs: 30,
            seed: 0,
            schedule: Schedule::default(),
        }
    }
}

/// A trained PCA simulator.
#[derive(Debug)]
pub struct PcaSimulator {
    pub pca: PositionPca,
    /// Codes are multiplied by this before the MLP (1/m).
    pub scale: f64,
    pub params: ParamStore,
    pub mlp: LatentSimulator,
}

/// The per-window tensors of a set of frames: `z_{m−2}`, `z_{m−1}`, `q_m`, `z_m`.
struct Windows {
    z2: Tensor,
    z1: Tensor,
    q: Tensor,
    z: Tensor,
}

fn codes_of(data: &EmbedData, pca: &PositionPca, scale: f64, frames: &[FrameRef], back: usize) -> Vec<f32> {
    frames
        .iter()
        .flat_map(|f| {
            let x = data.dataset.sequences[f.sequence].frame(f.frame - back);
            pca.encode(x).into_iter().map(move |c| (c * scale) as f32)
        })
        .collect()
}

fn windows(data: &EmbedData, pca: &PositionPca, scale: f64, frames: &[FrameRef]) -> Result<Windows> {
    let (n, k) = (frames.len(), pca.num_components());
    let device = &Device::Cpu;
    let code = |back| Tensor::from_vec(codes_of(data, pca, scale, frames, back), (n, k), device);
    Ok(Windows {
        z2: code(2)?,
        z1: code(1)?,
        z: code(0)?,
        q: data.control_batch(frames, device)?,
    })
}

struct Training<'a> {
    mlp: &'a LatentSimulator,
    params: &'a ParamStore,
    adam: AdamSettings,
    train: Windows,
    validation: Windows,
}

fn sim_loss(mlp: &LatentSimulator, w: &Windows, rows: Option<&[usize]>) -> Result<Tensor> {
    let pick = |t: &Tensor| -> Result<Tensor> {
        Ok(match rows {
            Some(r) => {
                let idx: Vec<u32> = r.iter().map(|&i| i as u32).collect();
                t.index_select(&Tensor::from_vec(idx, r.len(), t.device())?, 0)?
            }
            None => t.clone(),
        })
    };
    let predicted = mlp.step(&pick(&w.z2)?, &pick(&w.z1)?, &pick(&w.q)?)?;
    Ok((predicted - pick(&w.z)?)?.sqr()?.sum(1)?.mean_all()?)
}

impl Trainable for Training<'_> {
    fn groups(&self) -> Vec<Group<'_>> {
        vec![Group {
            name: "simulator",
            params: self.params,
            adam: self.adam,
        }]
    }

    fn num_examples(&self) -> usize {
        self.train.z.dim(0).unwrap_or(0)
    }

    fn batch_loss(&mut self, batch: &[usize], _at: BatchAt) -> Result<BatchLoss> {
        Ok(BatchLoss::Loss {
            loss: sim_loss(self.mlp, &self.train, Some(batch))?,
            terms: vec![],
        })
    }

    fn validation_score(&mut self) -> Result<f64> {
        if self.validation.z.dim(0)? == 0 {
            return Err(Error::InvalidParameter {
                name: "validation split",
                value: "0 windows".into(),
                reason: "model selection needs validation windows",
            });
        }
        Ok(sim_loss(self.mlp, &self.validation, None)?
            .to_dtype(DType::F64)?
            .to_scalar::<f64>()?)
    }
}

/// Trains (or continues) the simulator on `data`'s training windows in the run directory
/// `dir` (the one trainer: validation windows select the kept epoch), on the codes of `pca`.
pub fn train(
    dir: &std::path::Path,
    data: &EmbedData,
    pca: PositionPca,
    config: &PcaSimulatorSettings,
    observer: &mut dyn Observer,
) -> Result<PcaSimulator> {
    let k = pca.num_components();
    let mean_variance = pca.variances().iter().sum::<f64>() / k.max(1) as f64;
    if !(mean_variance > 0.0) {
        return Err(Error::InvalidParameter {
            name: "PCA",
            value: format!("{k} components"),
            reason: "spans no variance to simulate in",
        });
    }
    let scale = 1.0 / mean_variance.sqrt();
    let mut params = ParamStore::new(&Device::Cpu, config.seed ^ 0x5151_5151);
    let mlp = LatentSimulator::new(
        &mut params,
        LatentSimulatorSettings {
            latent: k,
            controls: 3 * data.dataset.grasp.len(),
            hidden: config.hidden.clone(),
        },
    )?;
    let mut training = Training {
        mlp: &mlp,
        params: &params,
        adam: config.adam,
        train: windows(data, &pca, scale, &data.train_windows)?,
        validation: windows(data, &pca, scale, &data.validation_windows)?,
    };
    let trainer = Trainer::new(
        format!("pca-simulator/{}", data.dataset.name),
        TrainerSettings {
            epochs: config.epochs,
            batch: config.batch,
            seed: config.seed,
            schedule: config.schedule,
        },
    );
    trainer.run(dir, &mut training, observer)?;
    Ok(PcaSimulator {
        pca,
        scale,
        params,
        mlp,
    })
}

impl PcaSimulator {
    /// A roll-out from the frames `a`, `b` (flat positions, m): one predicted frame per
    /// control in `controls` (3 per grasped vertex), each predicted code feeding the next
    /// step, decoded through the PCA basis.
    pub fn rollout(&self, a: &[f64], b: &[f64], controls: &[&[f64]]) -> Result<Vec<Vec<f64>>> {
        let k = self.pca.num_components();
        let device = &Device::Cpu;
        let code = |x: &[f64]| -> Result<Tensor> {
            let z: Vec<f32> = self.pca.encode(x).iter().map(|c| (c * self.scale) as f32).collect();
            Ok(Tensor::from_vec(z, (1, k), device)?)
        };
        let (mut z2, mut z1) = (code(a)?, code(b)?);
        let mut out = Vec::with_capacity(controls.len());
        for q in controls {
            let qt = crate::convert::f64_to_tensor("controls", q, &[1, q.len()], device)?;
            let z = self.mlp.step(&z2, &z1, &qt)?;
            let zs: Vec<f64> = crate::convert::tensor_to_f64("predicted code", &z)?
                .iter()
                .map(|c| c / self.scale)
                .collect();
            out.push(self.pca.decode(&zs));
            (z2, z1) = (z1, z);
        }
        Ok(out)
    }
}
