//! Adam (Kingma & Ba 2015, Algorithm 1) with its state in tensors a checkpoint can hold.
//!
//! candle-nn's `AdamW` keeps its moments private, so a resumed run would restart them
//! from zero and diverge from an uninterrupted one. This one exposes them: a checkpoint
//! stores the first and second moments and the step count, and training resumed from it
//! continues bit for bit.

use std::collections::BTreeMap;

use candle_core::backprop::GradStore;
use candle_core::{Tensor, Var};

use crate::error::{Error, Result};
use crate::params::Params;

/// Adam's hyper-parameters.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
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

/// Adam over every parameter of a [`Params`].
#[derive(Debug)]
pub struct Adam {
    pub settings: AdamSettings,
    step: u64,
    moments: BTreeMap<String, (Tensor, Tensor)>,
}

impl Adam {
    pub fn new(params: &Params, settings: AdamSettings) -> Result<Self> {
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
            .map(|(k, v)| Ok((k.clone(), (v.zeros_like()?, v.zeros_like()?))))
            .collect::<Result<_>>()?;
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
    pub fn step(&mut self, params: &Params, grads: &GradStore) -> Result<()> {
        let mut updates: Vec<(&String, &Var, Tensor, Tensor)> = Vec::new();
        for (name, var) in params.vars() {
            let Some(g) = grads.get(var.as_tensor()) else { continue };
            let g2 = g.sqr()?;
            let sum: f32 = g2.sum_all()?.to_scalar()?;
            if !sum.is_finite() {
                return Err(Error::NonFinite {
                    what: "gradient",
                    index: 0,
                });
            }
            let (m, v) = &self.moments[name];
            let s = &self.settings;
            let m = ((m * s.beta1)? + (g * (1.0 - s.beta1))?)?;
            let v = ((v * s.beta2)? + (g2 * (1.0 - s.beta2))?)?;
            updates.push((name, var, m, v));
        }
        self.step += 1;
        let t = self.step as i32;
        let s = self.settings;
        let (c1, c2) = (1.0 - s.beta1.powi(t), 1.0 - s.beta2.powi(t));
        for (name, var, m, v) in updates {
            let m_hat = (&m / c1)?;
            let v_hat = (&v / c2)?;
            let delta = (m_hat / (v_hat.sqrt()? + s.epsilon)?)?;
            var.set(&(var.as_tensor() - (delta * s.learning_rate)?)?)?;
            self.moments.insert(name.clone(), (m, v));
        }
        Ok(())
    }

    /// The state as named tensors: `adam.m/<name>`, `adam.v/<name>` and the step count.
    pub fn state(&self) -> (BTreeMap<String, Tensor>, u64) {
        let mut out = BTreeMap::new();
        for (k, (m, v)) in &self.moments {
            out.insert(format!("adam.m/{k}"), m.clone());
            out.insert(format!("adam.v/{k}"), v.clone());
        }
        (out, self.step)
    }

    /// Restores the state written by [`Adam::state`].
    pub fn restore(&mut self, tensors: &BTreeMap<String, Tensor>, step: u64, source: &str) -> Result<()> {
        for (k, (m, v)) in self.moments.iter_mut() {
            for (prefix, slot) in [("adam.m", m), ("adam.v", v)] {
                let key = format!("{prefix}/{k}");
                let t = tensors.get(&key).ok_or_else(|| Error::Checkpoint {
                    path: source.to_string(),
                    reason: format!("missing optimiser state {key}"),
                })?;
                if t.dims() != slot.dims() {
                    return Err(Error::Checkpoint {
                        path: source.to_string(),
                        reason: format!("optimiser state {key} has shape {:?}", t.dims()),
                    });
                }
                *slot = t.clone();
            }
        }
        self.step = step;
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
        let mut p = Params::new(&Device::Cpu, 1);
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
        let mut p = Params::new(&Device::Cpu, 2);
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
