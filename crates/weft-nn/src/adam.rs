//! Adam (Kingma & Ba 2015, Algorithm 1) with its state in tensors a checkpoint can hold.
//!
//! candle-nn's `AdamW` keeps its moments private, so a resumed run would restart them
//! from zero and diverge from an uninterrupted one. This one exposes them: a checkpoint
//! stores the first and second moments and the step count, and training resumed from it
//! continues bit for bit.

use std::collections::BTreeMap;

use candle_core::backprop::GradStore;
use candle_core::{Tensor, Var};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::params::ParamStore;

/// Adam's hyper-parameters.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct AdamSettings {
    pub learning_rate: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub epsilon: f64,
}

impl Default for AdamSettings {
    fn default() -> Self {
        Self {
            learning_rate: 1e-3,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
        }
    }
}

/// Adam over every parameter of a [`ParamStore`].
///
/// The moments live in plain `Vec<f32>`s and each step is one fused loop per parameter:
/// written as tensor operations, a step allocated a dozen temporaries the size of the
/// encoder's and decoder's dense layers (2 × 19.5 MB at 4225 vertices), and training
/// spent more time in page faults than in arithmetic (docs/EMBEDDING.md, *Training cost*).
#[derive(Debug)]
pub struct Adam {
    pub settings: AdamSettings,
    step: u64,
    moments: BTreeMap<String, Moments>,
}

/// First and second moments of one parameter, in its row-major order.
#[derive(Debug, Clone)]
struct Moments {
    shape: Vec<usize>,
    m: Vec<f32>,
    v: Vec<f32>,
}

fn values(t: &Tensor) -> Result<Vec<f32>> {
    Ok(t.flatten_all()?.to_vec1::<f32>()?)
}

impl Adam {
    pub fn new(params: &ParamStore, settings: AdamSettings) -> Result<Self> {
        if !(settings.learning_rate > 0.0
            && (0.0..1.0).contains(&settings.beta1)
            && (0.0..1.0).contains(&settings.beta2))
        {
            return Err(Error::InvalidParameter {
                name: "Adam settings",
                value: format!("{settings:?}"),
                reason: "needs a positive learning rate and betas in [0, 1)",
            });
        }
        let moments = params
            .vars()
            .iter()
            .map(|(k, v)| {
                let n = v.elem_count();
                let moments = Moments {
                    shape: v.dims().to_vec(),
                    m: vec![0.0; n],
                    v: vec![0.0; n],
                };
                (k.clone(), moments)
            })
            .collect();
        Ok(Self {
            settings,
            step: 0,
            moments,
        })
    }

    /// Steps taken so far.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// One Adam step on every parameter that has a gradient in `grads`. A non-finite
    /// gradient is an error and changes nothing.
    pub fn step(&mut self, params: &ParamStore, grads: &GradStore) -> Result<()> {
        self.step_scaled(params, grads, 1.0)
    }

    /// One Adam step on the gradients multiplied by `scale` (gradient clipping: the
    /// trainer scales every group by one factor so the global norm stays bounded).
    /// Multiplying by 1 is exact, so an unclipped step is [`Adam::step`] bit for bit.
    pub fn step_scaled(&mut self, params: &ParamStore, grads: &GradStore, scale: f64) -> Result<()> {
        let scale = scale as f32;
        // Every gradient is checked before any parameter changes.
        let mut gradients: Vec<(&String, &Var, &Tensor)> = Vec::new();
        for (name, var) in params.vars() {
            let Some(g) = grads.get(var.as_tensor()) else { continue };
            if g.elem_count() != var.elem_count() {
                return Err(Error::Shape {
                    what: "Adam gradient",
                    expected: format!("{:?}", var.dims()),
                    got: format!("{:?}", g.dims()),
                });
            }
            let bad = crate::convert::with_f32_values(g, |g| {
                const BLOCK: usize = 1 << 14;
                g.par_chunks(BLOCK).enumerate().find_map_first(|(k, block)| {
                    block
                        .iter()
                        .position(|x| !(*x * scale).is_finite())
                        .map(|i| k * BLOCK + i)
                })
            })?;
            if let Some(index) = bad {
                return Err(Error::NonFinite {
                    what: "gradient",
                    index,
                });
            }
            gradients.push((name, var, g));
        }
        self.step += 1;
        let t = self.step as i32;
        let s = self.settings;
        let (b1, b2) = (s.beta1 as f32, s.beta2 as f32);
        let (c1, c2) = ((1.0 - s.beta1.powi(t)) as f32, (1.0 - s.beta2.powi(t)) as f32);
        let (lr, eps) = (s.learning_rate as f32, s.epsilon as f32);
        for (name, var, g) in gradients {
            let state = self.moments.get_mut(name).ok_or_else(|| Error::Shape {
                what: "Adam step",
                expected: "a parameter the optimiser was built with".into(),
                got: format!("new parameter {name}"),
            })?;
            let Moments { m, v, .. } = state;
            crate::convert::with_f32_values(g, |g| {
                var.as_tensor().inplace_op1(&Update {
                    g,
                    m: std::sync::Mutex::new((m.as_mut_slice(), v.as_mut_slice())),
                    scale,
                    b1,
                    b2,
                    c1,
                    c2,
                    lr,
                    eps,
                })
            })??;
        }
        Ok(())
    }

    /// The learning rate of the next step.
    pub fn learning_rate(&self) -> f64 {
        self.settings.learning_rate
    }

    /// The state as named tensors: `adam.m/<name>`, `adam.v/<name>` and the step count.
    pub fn state(&self, device: &candle_core::Device) -> Result<(BTreeMap<String, Tensor>, u64)> {
        let mut out = BTreeMap::new();
        for (k, st) in &self.moments {
            out.insert(
                format!("adam.m/{k}"),
                Tensor::from_slice(&st.m, st.shape.as_slice(), device)?,
            );
            out.insert(
                format!("adam.v/{k}"),
                Tensor::from_slice(&st.v, st.shape.as_slice(), device)?,
            );
        }
        Ok((out, self.step))
    }

    /// Restores the state written by [`Adam::state`].
    pub fn restore(&mut self, tensors: &BTreeMap<String, Tensor>, step: u64, source: &str) -> Result<()> {
        for (k, st) in self.moments.iter_mut() {
            for (prefix, slot) in [("adam.m", &mut st.m), ("adam.v", &mut st.v)] {
                let key = format!("{prefix}/{k}");
                let t = tensors.get(&key).ok_or_else(|| Error::Checkpoint {
                    path: source.to_string(),
                    reason: format!("missing optimiser state {key}"),
                })?;
                if t.dims() != st.shape.as_slice() {
                    return Err(Error::Checkpoint {
                        path: source.to_string(),
                        reason: format!("optimiser state {key} has shape {:?}", t.dims()),
                    });
                }
                *slot = values(t)?;
            }
        }
        self.step = step;
        Ok(())
    }
}

/// The squared Euclidean norm of the gradients `grads` holds for `params`.
pub fn gradient_sq_norm(params: &ParamStore, grads: &GradStore) -> Result<f64> {
    let mut sum = 0.0f64;
    for var in params.vars().values() {
        if let Some(g) = grads.get(var.as_tensor()) {
            sum += values(g)?.iter().map(|x| f64::from(*x).powi(2)).sum::<f64>();
        }
    }
    Ok(sum)
}

/// One parameter's Adam update, in place in the parameter's storage (a copy out and back
/// of a 4.9 M-value layer cost more than the update), parallel over blocks.
struct Update<'a> {
    g: &'a [f32],
    m: std::sync::Mutex<(&'a mut [f32], &'a mut [f32])>,
    scale: f32,
    b1: f32,
    b2: f32,
    c1: f32,
    c2: f32,
    lr: f32,
    eps: f32,
}

impl candle_core::InplaceOp1 for Update<'_> {
    fn name(&self) -> &'static str {
        "adam-update"
    }

    fn cpu_fwd(&self, storage: &mut candle_core::CpuStorage, layout: &candle_core::Layout) -> candle_core::Result<()> {
        let (a, b) = layout
            .contiguous_offsets()
            .ok_or_else(|| candle_core::Error::Msg("Adam: the parameter must be contiguous".into()))?;
        let p = match storage {
            candle_core::CpuStorage::F32(p) => &mut p[a..b],
            _ => return Err(candle_core::Error::Msg("Adam: f32 parameters only".into())),
        };
        let mut moments = self
            .m
            .lock()
            .map_err(|_| candle_core::Error::Msg("Adam: poisoned moments".into()))?;
        let (m, v) = &mut *moments;
        let Self {
            scale,
            b1,
            b2,
            c1,
            c2,
            lr,
            eps,
            ..
        } = *self;
        const BLOCK: usize = 1 << 14;
        p.par_chunks_mut(BLOCK)
            .zip(self.g.par_chunks(BLOCK))
            .zip(m.par_chunks_mut(BLOCK))
            .zip(v.par_chunks_mut(BLOCK))
            .for_each(|(((p, g), m), v)| {
                for (((p, &g), m), v) in p.iter_mut().zip(g).zip(m).zip(v) {
                    // Multiplying by 1 is exact: an unclipped step is the plain one.
                    let g = if scale != 1.0 { g * scale } else { g };
                    *m = b1 * *m + (1.0 - b1) * g;
                    *v = b2 * *v + (1.0 - b2) * g * g;
                    *p -= lr * ((*m / c1) / ((*v / c2).sqrt() + eps));
                }
            });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Init;
    use candle_core::Device;

    #[test]
    fn first_step_moves_each_weight_by_the_learning_rate_against_its_gradient_sign() {
        // Adam's first step is −lr · g/(|g| + ε/…) ≈ −lr · sign(g), whatever g's scale.
        let mut p = ParamStore::new(&Device::Cpu, 1);
        let w = p.create("w", &[3], Init::Uniform(1.0)).unwrap();
        let before: Vec<f32> = w.to_vec1().unwrap();
        let target = Tensor::new(&[10.0f32, -10.0, 0.5], &Device::Cpu).unwrap();
        let loss = (&w - &target).unwrap().sqr().unwrap().sum_all().unwrap();
        let grads = loss.backward().unwrap();
        let mut adam = Adam::new(&p, AdamSettings::default()).unwrap();
        adam.step(&p, &grads).unwrap();
        let after: Vec<f32> = p.vars()["w"].as_tensor().to_vec1().unwrap();
        for i in 0..3 {
            let g = 2.0 * (before[i] - [10.0, -10.0, 0.5][i]);
            let moved = after[i] - before[i];
            assert!((moved + 1e-3 * g.signum()).abs() < 1e-6, "{i}: moved {moved}, g {g}");
        }
        assert_eq!(adam.steps(), 1);
    }

    #[test]
    fn minimises_a_quadratic() {
        let mut p = ParamStore::new(&Device::Cpu, 2);
        let w = p.create("w", &[4], Init::Uniform(1.0)).unwrap();
        let target = Tensor::new(&[0.3f32, -0.7, 0.1, 0.9], &Device::Cpu).unwrap();
        let mut adam = Adam::new(
            &p,
            AdamSettings {
                learning_rate: 0.05,
                ..AdamSettings::default()
            },
        )
        .unwrap();
        let loss = |w: &Tensor| -> f32 {
            (w - &target)
                .unwrap()
                .sqr()
                .unwrap()
                .sum_all()
                .unwrap()
                .to_scalar()
                .unwrap()
        };
        let start = loss(&w);
        for _ in 0..400 {
            let l = (&w - &target).unwrap().sqr().unwrap().sum_all().unwrap();
            adam.step(&p, &l.backward().unwrap()).unwrap();
        }
        assert!(loss(&w) < 1e-4 * start, "{} → {}", start, loss(&w));
    }
}
