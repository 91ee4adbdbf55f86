//! Trainable parameters with seeded initialisation.
//!
//! candle's own initialisers draw from a thread-local generator that cannot be seeded, so
//! two runs of the same configuration would start from different weights. Every
//! parameter here is drawn from weft's SplitMix64 instead, in the order the model asks for
//! them, and stored under a stable name: the same seed gives the same network, bit for
//! bit, on every machine.

use std::collections::BTreeMap;

use candle_core::{DType, Device, Tensor, Var};
use weft_sim::rng::SplitMix64;

use crate::error::{Error, Result};

/// How a parameter starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Init {
    Zeros,
    /// Uniform in `±bound`.
    Uniform(f64),
    /// Every entry equal to the value.
    Constant(f64),
}

impl Init {
    /// He/Kaiming uniform for a layer followed by a leaky ReLU of `slope`: bound
    /// `√(6 / ((1 + slope²) fan_in))`, which keeps activations' variance through depth.
    pub fn kaiming(fan_in: usize, slope: f64) -> Self {
        Init::Uniform((6.0 / ((1.0 + slope * slope) * fan_in.max(1) as f64)).sqrt())
    }
}

/// Named trainable parameters (f32), in a stable order.
#[derive(Debug)]
pub struct ParamStore {
    device: Device,
    vars: BTreeMap<String, Var>,
    rng: SplitMix64,
}

impl ParamStore {
    /// An empty store whose initialisations are drawn from SplitMix64(`seed`).
    pub fn new(device: &Device, seed: u64) -> Self {
        Self {
            device: device.clone(),
            vars: BTreeMap::new(),
            rng: SplitMix64::new(seed),
        }
    }

    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Creates parameter `name` of `shape`, initialised by `init`, and returns it as a
    /// tensor that tracks gradients. Names must be unique.
    pub fn create(&mut self, name: &str, shape: &[usize], init: Init) -> Result<Tensor> {
        if self.vars.contains_key(name) {
            return Err(Error::InvalidParameter {
                name: "parameter name",
                value: name.to_string(),
                reason: "already used by another parameter",
            });
        }
        let n: usize = shape.iter().product();
        let values: Vec<f32> = match init {
            Init::Zeros => vec![0.0; n],
            Init::Uniform(bound) => (0..n).map(|_| self.rng.uniform(-bound, bound) as f32).collect(),
            Init::Constant(c) => vec![c as f32; n],
        };
        let var = Var::from_tensor(&Tensor::from_vec(values, shape, &self.device)?)?;
        let t = var.as_tensor().clone();
        self.vars.insert(name.to_string(), var);
        Ok(t)
    }

    pub fn vars(&self) -> &BTreeMap<String, Var> {
        &self.vars
    }

    pub fn num_parameters(&self) -> usize {
        self.vars.values().map(|v| v.elem_count()).sum()
    }

    /// The parameters as named tensors (for saving).
    pub fn tensors(&self) -> BTreeMap<String, Tensor> {
        self.vars
            .iter()
            .map(|(k, v)| (k.clone(), v.as_tensor().clone()))
            .collect()
    }

    /// Overwrites every parameter from `tensors`, which must hold exactly these names with
    /// these shapes (`source` names where they came from, for the error).
    pub fn assign(&self, tensors: &BTreeMap<String, Tensor>, source: &str) -> Result<()> {
        for (name, var) in &self.vars {
            let t = tensors.get(name).ok_or_else(|| Error::Checkpoint {
                path: source.to_string(),
                reason: format!("missing parameter {name}"),
            })?;
            if t.dims() != var.dims() {
                return Err(Error::Checkpoint {
                    path: source.to_string(),
                    reason: format!("parameter {name} has shape {:?}, the model {:?}", t.dims(), var.dims()),
                });
            }
            var.set(&t.to_dtype(DType::F32)?.to_device(&self.device)?)?;
        }
        if let Some(extra) = tensors.keys().find(|k| !self.vars.contains_key(*k)) {
            return Err(Error::Checkpoint {
                path: source.to_string(),
                reason: format!("parameter {extra} is not in this model"),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_weights_and_duplicate_names_rejected() {
        let d = Device::Cpu;
        let draw = |seed| {
            let mut p = ParamStore::new(&d, seed);
            let a = p.create("a", &[3, 4], Init::kaiming(3, 0.2)).unwrap();
            let b = p.create("b", &[4], Init::Zeros).unwrap();
            assert!(p.create("a", &[1], Init::Zeros).is_err());
            assert_eq!(p.num_parameters(), 16);
            (
                a.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
                b.to_vec1::<f32>().unwrap(),
            )
        };
        let (a1, b1) = draw(7);
        let (a2, _) = draw(7);
        let (a3, _) = draw(8);
        assert_eq!(a1, a2);
        assert_ne!(a1, a3);
        assert!(b1.iter().all(|&x| x == 0.0));
        let bound = (6.0f64 / (1.04 * 3.0)).sqrt() as f32;
        assert!(a1.iter().all(|x| x.abs() <= bound) && a1.iter().any(|x| x.abs() > 0.5 * bound));
    }
}
