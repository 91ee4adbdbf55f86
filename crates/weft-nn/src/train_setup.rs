//! What a training command settles before it trains, from its files and flags: the JSON
//! configuration (or the default), the overrides every command takes (seed, learning rate,
//! epochs), the refusal to overwrite a model, and altconv's default window fitted to the
//! sequences of the data. It neither trains (the `train_model` functions and
//! [`crate::drape`] do) nor prints.

use std::path::Path;

use serde::de::DeserializeOwned;

use crate::{Error, Result};

/// Reads a JSON configuration file, or the default without one.
pub fn read_config<T: DeserializeOwned + Default>(path: Option<&Path>) -> Result<T> {
    let Some(path) = path else { return Ok(T::default()) };
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
        path: path.display().to_string(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|e| Error::ConfigFile {
        path: path.display().to_string(),
        reason: e.to_string(),
    })
}

/// Whether the configuration file at `path` (if any) sets `field` itself.
pub fn sets_field(path: Option<&Path>, field: &str) -> Result<bool> {
    let Some(path) = path else { return Ok(false) };
    let value: serde_json::Value = read_config(Some(path))?;
    Ok(value.get(field).is_some())
}

/// The values every training command may set over its configuration's.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Overrides {
    pub seed: Option<u64>,
    pub learning_rate: Option<f64>,
    /// Of every stage (or the one count) the configuration has.
    pub epochs: Option<usize>,
}

impl Overrides {
    /// Writes the overrides given into a configuration's fields.
    pub fn apply(&self, seed: &mut u64, learning_rate: &mut f64, epochs: &mut [usize]) {
        if let Some(s) = self.seed {
            *seed = s;
        }
        if let Some(l) = self.learning_rate {
            *learning_rate = l;
        }
        if let Some(e) = self.epochs {
            epochs.iter_mut().for_each(|x| *x = e);
        }
    }
}

/// Refuses to overwrite the model in `out` unless asked to continue it.
pub fn refuse_overwrite(out: &Path, resume: bool) -> Result<()> {
    let holds = out.join("config.json").exists() || out.join("training.json").exists();
    if holds && !resume {
        return Err(Error::ModelExists {
            dir: out.display().to_string(),
        });
    }
    Ok(())
}

/// A teacher-forced window shortened to what the data holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StepsFit {
    /// The dataset's directory.
    pub data: std::path::PathBuf,
    /// The steps asked for (they need one frame more).
    pub asked: usize,
    /// The frames of the shortest training or validation sequence; training runs
    /// `frames - 1` steps.
    pub frames: usize,
}

impl std::fmt::Display for StepsFit {
    /// What a command says when it shortens the window.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "altconv: {} steps need {} frames and {}'s shortest sequence holds {}: training on {} steps (set \
             `steps` in a --config to choose)",
            self.asked,
            self.asked + 1,
            self.data.display(),
            self.frames,
            self.frames - 1
        )
    }
}

/// Shortens the teacher-forced window of `config` to what `dataset`'s training and
/// validation sequences hold (a `--size quick` dataset's hold 9 frames, the default window
/// needs 21) and says by how much; a window the data holds is kept as it is (`None`).
pub fn fit_altconv_steps(
    config: &mut crate::altconv::AltConvTrainingSettings,
    dataset: &weft_data::LimbDataset,
) -> Option<StepsFit> {
    let shortest = ["train", "validation"]
        .iter()
        .flat_map(|split| dataset.split(split))
        .map(|s| s.skinned.len())
        .min();
    let frames = shortest.filter(|&f| f >= 2 && f <= config.steps)?;
    let fit = StepsFit {
        data: dataset.dir.clone(),
        asked: config.steps,
        frames,
    };
    config.steps = frames - 1;
    Some(fit)
}

/// The embed configuration at `path` (or the default) under `overrides`: `no_pb` is the
/// "\[46\] + L_vert" baseline (λ_ephys = λ_mphys = 0); `autograd` trains through candle's
/// autograd instead of the fused kernels. Checked, with the `stages` asked for.
pub fn embed_config(
    path: Option<&Path>,
    overrides: &Overrides,
    no_pb: bool,
    autograd: bool,
    stages: &[u8],
) -> Result<crate::embed::EmbedTrainingSettings> {
    let mut config: crate::embed::EmbedTrainingSettings = read_config(path)?;
    if no_pb {
        config.weights.ephys = 0.0;
        config.weights.mphys = 0.0;
    }
    overrides.apply(&mut config.seed, &mut config.adam.learning_rate, &mut config.epochs);
    if autograd {
        config.kernels = crate::Kernels::Autograd;
    }
    config.validate()?;
    if let Some(&s) = stages.iter().find(|s| !(1..=3).contains(*s)) {
        return Err(Error::InvalidParameter {
            name: "stage",
            value: s.to_string(),
            reason: "does not exist (stages are 1, 2 and 3)",
        });
    }
    Ok(config)
}

/// The configuration of altconv `variant` at `path` (or the variant's default) under
/// `overrides`, checked.
pub fn altconv_config(
    path: Option<&Path>,
    overrides: &Overrides,
    variant: crate::altconv::Variant,
    autograd: bool,
) -> Result<crate::altconv::AltConvTrainingSettings> {
    let mut config = match path {
        Some(_) => read_config(path)?,
        None => crate::altconv::AltConvTrainingSettings::new(variant),
    };
    config.variant = variant;
    overrides.apply(
        &mut config.seed,
        &mut config.adam.learning_rate,
        std::slice::from_mut(&mut config.epochs),
    );
    if autograd {
        config.kernels = crate::altconv::Kernels::Autograd;
    }
    config.validate()?;
    Ok(config)
}

/// The NNWarp configuration at `path` (or the default) for `material` under `overrides`,
/// checked; a configuration naming another material is refused.
pub fn nnwarp_config(
    path: Option<&Path>,
    overrides: &Overrides,
    material: &str,
) -> Result<crate::nnwarp::WarpTrainingSettings> {
    let mut config: crate::nnwarp::WarpTrainingSettings = read_config(path)?;
    if !config.material.is_empty() && config.material != material {
        return Err(Error::InvalidSettings {
            field: "material".into(),
            value: format!("{:?}", config.material),
            reason: "differs from --material",
        });
    }
    overrides.apply(
        &mut config.seed,
        &mut config.adam.learning_rate,
        std::slice::from_mut(&mut config.epochs),
    );
    config.validate()?;
    Ok(config)
}

/// The drape configuration at `path` (or the default) under `overrides` (epochs: of the
/// pre-training and the fine-tuning), checked.
pub fn drape_config(path: Option<&Path>, overrides: &Overrides) -> Result<crate::drape::DrapeTrainingSettings> {
    let mut config: crate::drape::DrapeTrainingSettings = read_config(path)?;
    let mut epochs = [config.pretrain_epochs, config.finetune_epochs];
    overrides.apply(&mut config.seed, &mut config.learning_rate, &mut epochs);
    [config.pretrain_epochs, config.finetune_epochs] = epochs;
    config.validate()?;
    Ok(config)
}

/// The layer after a drape network, as a command names it (μ comes beside it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DrapeLayerKind {
    None,
    Socp,
    Quasistatic,
}

/// The layer a drape model trains through: `mu` is the quasistatic layer's μ, or where a
/// learned μ starts (default 0.1); `learn_mu` learns it (`Some(true)`: one μ per vertex).
/// Every μ of `scan_mu` must be positive and finite too.
pub fn drape_layer(
    kind: DrapeLayerKind,
    mu: Option<f64>,
    learn_mu: Option<bool>,
    scan_mu: &[f64],
) -> Result<crate::drape::Layer> {
    use crate::drape::Layer;
    let invalid = |name, value: String, reason| Err(Error::InvalidParameter { name, value, reason });
    let positive = |m: f64| m > 0.0 && m.is_finite();
    if let (Some(m), false) = (mu, kind == DrapeLayerKind::Quasistatic) {
        return invalid(
            "--mu",
            m.to_string(),
            "sets the quasistatic layer's μ; it needs --layer quasistatic",
        );
    }
    let mu = mu.unwrap_or(0.1);
    if !positive(mu) {
        return invalid("--mu", mu.to_string(), "must be positive and finite");
    }
    if let Some(m) = scan_mu.iter().find(|m| !positive(**m)) {
        return invalid("--scan-mu", m.to_string(), "values must be positive and finite");
    }
    Ok(match (kind, learn_mu) {
        (DrapeLayerKind::None, None) => Layer::None,
        (DrapeLayerKind::Socp, None) => Layer::Socp,
        (DrapeLayerKind::Quasistatic, None) => Layer::Quasistatic(mu),
        (DrapeLayerKind::Quasistatic, Some(per_vertex)) => Layer::LearnedMu { start: mu, per_vertex },
        (_, Some(per_vertex)) => {
            let value = if per_vertex { "per-vertex" } else { "global" };
            return invalid("--learn-mu", value.into(), "needs --layer quasistatic");
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drape_layers_take_mu_only_where_it_belongs() {
        use crate::drape::Layer;
        use DrapeLayerKind::*;
        assert!(matches!(
            drape_layer(None, Option::None, Option::None, &[]),
            Ok(Layer::None)
        ));
        assert!(
            matches!(drape_layer(Quasistatic, Some(0.5), Option::None, &[1.0]), Ok(Layer::Quasistatic(m)) if m == 0.5)
        );
        assert!(matches!(
            drape_layer(Quasistatic, Option::None, Some(true), &[]),
            Ok(Layer::LearnedMu { start, per_vertex: true }) if start == 0.1
        ));
        assert!(drape_layer(Socp, Some(0.5), Option::None, &[]).is_err());
        assert!(drape_layer(Quasistatic, Some(-1.0), Option::None, &[]).is_err());
        assert!(
            drape_layer(None, Option::None, Option::None, &[0.0])
                .unwrap_err()
                .to_string()
                .contains("--scan-mu")
        );
        assert!(drape_layer(Socp, Option::None, Some(false), &[]).is_err());
    }

    #[test]
    fn overrides_replace_only_what_they_give() {
        let (mut seed, mut lr, mut epochs) = (1, 1e-3, [30, 30, 10]);
        Overrides::default().apply(&mut seed, &mut lr, &mut epochs);
        assert_eq!((seed, lr, epochs), (1, 1e-3, [30, 30, 10]));
        let o = Overrides {
            seed: Some(7),
            learning_rate: None,
            epochs: Some(2),
        };
        o.apply(&mut seed, &mut lr, &mut epochs);
        assert_eq!((seed, lr, epochs), (7, 1e-3, [2, 2, 2]));
    }

    #[test]
    fn configuration_files_are_read_checked_and_defaulted() {
        let dir = std::env::temp_dir().join(format!("weft-nn-train-setup-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("good.json");
        std::fs::write(&good, r#"{"steps": 4}"#).unwrap();
        let bad = dir.join("bad.json");
        std::fs::write(&bad, "{").unwrap();
        let v: serde_json::Value = read_config(Some(&good)).unwrap();
        assert_eq!(v["steps"], 4);
        assert!(sets_field(Some(&good), "steps").unwrap());
        assert!(!sets_field(Some(&good), "epochs").unwrap() && !sets_field(None, "steps").unwrap());
        assert!(matches!(
            read_config::<serde_json::Value>(Some(&bad)),
            Err(Error::ConfigFile { .. })
        ));
        assert!(matches!(
            read_config::<serde_json::Value>(Some(&dir.join("missing.json"))),
            Err(Error::Io { .. })
        ));
        assert_eq!(read_config::<u32>(None).unwrap(), 0);
        refuse_overwrite(&dir, false).unwrap();
        std::fs::write(dir.join("config.json"), "{}").unwrap();
        assert!(matches!(refuse_overwrite(&dir, false), Err(Error::ModelExists { .. })));
        refuse_overwrite(&dir, true).unwrap();
        let o = Overrides {
            epochs: Some(4),
            ..Default::default()
        };
        assert_eq!(embed_config(None, &o, true, false, &[1, 2]).unwrap().epochs, [4; 3]);
        assert!(embed_config(None, &o, false, false, &[4]).is_err());
        assert_eq!(drape_config(None, &o).unwrap().finetune_epochs, 4);
        std::fs::write(&good, r#"{"material": "stvk"}"#).unwrap();
        assert!(nnwarp_config(Some(&good), &o, "neo-hookean").is_err());
        assert_eq!(nnwarp_config(Some(&good), &o, "stvk").unwrap().epochs, 4);
        let alt = crate::altconv::Variant::from_name("alt").unwrap();
        assert_eq!(altconv_config(None, &o, alt, true).unwrap().epochs, 4);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
