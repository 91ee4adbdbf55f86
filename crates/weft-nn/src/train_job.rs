//! A training command's run, from its files and flags to the lines it reports: each
//! model's job settles its configuration ([`crate::train_setup`]), refuses to overwrite a
//! model, loads its dataset and checks it fits, then trains with progress bars and
//! summarises. It does not print: a job gives the lines to say before training
//! ([`TrainJob::notes`], [`TrainJob::start`]) and its [`TrainReport`] those after; xtask
//! prints them.

use std::path::Path;

use crate::progress::TrainProgress;
use crate::train_setup::{
    DrapeLayerKind, Overrides, altconv_config, drape_config, drape_layer, embed_config, fit_altconv_steps,
    nnwarp_config, refuse_overwrite, sets_field,
};
use crate::trainer::TrainingState;
use crate::{Error, Result};

/// What every training command is given besides its model's own flags.
#[derive(Debug, Clone, Copy)]
pub struct TrainParams<'a> {
    /// The dataset directory.
    pub data: &'a Path,
    /// The model directory written (or continued with `resume`).
    pub out: &'a Path,
    /// A JSON configuration file (the default without one).
    pub config: Option<&'a Path>,
    pub overrides: Overrides,
    pub resume: bool,
    /// No progress bars and no epoch lines.
    pub quiet: bool,
    /// Through candle's autograd instead of the fused kernels (embed, altconv).
    pub autograd: bool,
}

/// What a training run reports once it is done, line by line (the last names the model).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TrainReport {
    pub lines: Vec<String>,
}

impl TrainReport {
    fn new(mut lines: Vec<String>, out: &Path) -> Self {
        lines.push(format!("model → {}", out.display()));
        Self { lines }
    }
}

/// A training run ready to start: its dataset read and its configuration checked.
pub trait TrainJob {
    /// What the command settled from the data, said before [`TrainJob::start`] checks it
    /// (altconv's fitted window).
    fn notes(&self) -> &[String] {
        &[]
    }
    /// Checks what the data settled and says what the run trains on.
    fn start(&self) -> Result<Vec<String>>;
    /// Trains (with progress bars unless quiet) and summarises.
    fn run(self) -> Result<TrainReport>;
}

/// Reads a dataset, naming its directory when that fails.
fn load<T, E: Into<Error>>(data: &Path, read: impl FnOnce(&Path) -> Result<T, E>) -> Result<T> {
    read(data).map_err(|e| Error::Load {
        path: data.display().to_string(),
        source: Box::new(e.into()),
    })
}

/// The embedding's stages (§VI-A) on a cloth dataset.
#[derive(Debug)]
pub struct EmbedJob<'a> {
    params: TrainParams<'a>,
    config: crate::embed::EmbedTrainingSettings,
    data: crate::embed::EmbedData,
    name: String,
    stages: &'a [u8],
}

impl<'a> EmbedJob<'a> {
    /// `no_pb` is the "\[46\] + L_vert" baseline; `stages` those to run.
    pub fn new(params: TrainParams<'a>, no_pb: bool, stages: &'a [u8]) -> Result<Self> {
        let config = embed_config(params.config, &params.overrides, no_pb, params.autograd, stages)?;
        refuse_overwrite(params.out, params.resume)?;
        let dataset = load(params.data, weft_data::ClothDataset::load)?;
        let name = dataset.name.clone();
        let data = crate::embed::EmbedData::new(dataset)?;
        Ok(Self {
            params,
            config,
            data,
            name,
            stages,
        })
    }
}

impl TrainJob for EmbedJob<'_> {
    fn start(&self) -> Result<Vec<String>> {
        let (data, config, name) = (&self.data, &self.config, &self.name);
        Ok(vec![format!(
            "{name}: {} training and {} validation windows, {} vertices; L_phys scale {:?} {:.4e} m²/J (inertial \
             Δt²/m̄ {:.4e}, curvature 1/mean diag H {:.4e})",
            data.train_windows.len(),
            data.validation_windows.len(),
            data.num_vertices(),
            config.phys_scale,
            data.phys_scale(config.phys_scale),
            data.inertial_scale,
            data.curvature_scale
        )])
    }

    fn run(self) -> Result<TrainReport> {
        let (p, name) = (self.params, &self.name);
        let mut progress = TrainProgress::new(p.quiet, &format!("embed/{name}"))?;
        let (_, states) = crate::embed::train_model(p.out, &self.data, &self.config, self.stages, &mut progress)?;
        drop(progress);
        Ok(TrainReport::new(stage_lines(name, &states), p.out))
    }
}

/// One line per stage trained: the epoch kept and its validation loss.
fn stage_lines(name: &str, states: &[(u8, TrainingState)]) -> Vec<String> {
    states
        .iter()
        .map(|(stage, s)| {
            format!(
                "{name}: stage {stage}: kept epoch {} of {}, validation loss {:.4e}",
                s.best_epoch, s.epochs_done, s.best_validation
            )
        })
        .collect()
}

/// NNWarp's correction MLP for one material (§5).
#[derive(Debug)]
pub struct NnwarpJob<'a> {
    params: TrainParams<'a>,
    config: crate::nnwarp::WarpTrainingSettings,
    dataset: weft_data::WarpDataset,
    material: &'a str,
}

impl<'a> NnwarpJob<'a> {
    pub fn new(params: TrainParams<'a>, material: &'a str) -> Result<Self> {
        let config = nnwarp_config(params.config, &params.overrides, material)?;
        refuse_overwrite(params.out, params.resume)?;
        let dataset = load(params.data, |d| weft_data::WarpDataset::load(d, material))?;
        Ok(Self {
            params,
            config,
            dataset,
            material,
        })
    }
}

impl TrainJob for NnwarpJob<'_> {
    fn start(&self) -> Result<Vec<String>> {
        Ok(Vec::new())
    }

    fn run(self) -> Result<TrainReport> {
        let (p, material) = (self.params, self.material);
        let mut progress = TrainProgress::new(p.quiet, &format!("nnwarp/{material}"))?;
        let (state, n_train, n_val) = crate::nnwarp::train_model(p.out, &self.dataset, &self.config, &mut progress)?;
        drop(progress);
        let line = format!(
            "nnwarp/{material}: {n_train} training and {n_val} validation pairs; kept epoch {} of {}, validation {:.4e}",
            state.best_epoch, state.epochs_done, state.best_validation
        );
        Ok(TrainReport::new(vec![line], p.out))
    }
}

/// Alt-ConvLSTM or a ConvLSTM baseline on the `limb` dataset (§5.1).
#[derive(Debug)]
pub struct AltconvJob<'a> {
    params: TrainParams<'a>,
    variant: crate::altconv::Variant,
    config: crate::altconv::AltConvTrainingSettings,
    dataset: weft_data::LimbDataset,
    notes: Vec<String>,
}

impl<'a> AltconvJob<'a> {
    /// `model` names the variant; a window the configuration file does not set is fitted
    /// to the sequences of the data ([`fit_altconv_steps`], said in the notes).
    pub fn new(params: TrainParams<'a>, model: &str) -> Result<Self> {
        let variant = crate::altconv::Variant::from_name(model)?;
        let mut config = altconv_config(params.config, &params.overrides, variant, params.autograd)?;
        refuse_overwrite(params.out, params.resume)?;
        let dataset = load(params.data, weft_data::LimbDataset::load)?;
        let mut notes = Vec::new();
        if !sets_field(params.config, "steps")? {
            notes.extend(fit_altconv_steps(&mut config, &dataset).map(|fit| fit.to_string()));
        }
        Ok(Self {
            params,
            variant,
            config,
            dataset,
            notes,
        })
    }
}

impl TrainJob for AltconvJob<'_> {
    fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Checks the window fitted to the data against the rest of the configuration.
    fn start(&self) -> Result<Vec<String>> {
        let (config, dataset) = (&self.config, &self.dataset);
        config.validate()?;
        Ok(vec![format!(
            "altconv/{}: {} training and {} validation sequences of {} steps, {} vertices",
            self.variant.name(),
            dataset.split("train").count(),
            dataset.split("validation").count(),
            config.steps,
            dataset.rest.num_vertices(),
        )])
    }

    fn run(self) -> Result<TrainReport> {
        let (p, name) = (self.params, self.variant.name());
        let mut progress = TrainProgress::new(p.quiet, &format!("altconv/{name}"))?;
        let trained = crate::altconv::train_model(p.out, &self.dataset, &self.config, &mut progress)?;
        drop(progress);
        let s = &trained.state;
        let mut lines = vec![format!(
            "altconv/{name}: kept epoch {} of {}, validation {:.3} mm",
            s.best_epoch,
            s.epochs_done,
            1e3 * s.best_validation
        )];
        if let Some(summary) = crate::altconv::validation_rollout(p.out, &self.dataset, &trained)? {
            lines.extend(summary.errors_mm.iter().map(|(model, mm)| {
                format!(
                    "altconv/{name}: {model} roll-out error over steps 1-{} of the validation sequences: {mm:.3} mm",
                    summary.steps
                )
            }));
        }
        Ok(TrainReport::new(lines, p.out))
    }
}

/// The nonlinear inertial correction, a one-step surrogate for the guard (docs/GUARD.md).
#[derive(Debug)]
pub struct InertialCorrectionMlpJob<'a> {
    params: TrainParams<'a>,
    config: crate::inertial_correction_mlp::InertialCorrectionMlpSettings,
    dataset: weft_data::ClothDataset,
}

impl<'a> InertialCorrectionMlpJob<'a> {
    pub fn new(params: TrainParams<'a>) -> Result<Self> {
        let mut config: crate::inertial_correction_mlp::InertialCorrectionMlpSettings =
            crate::train_setup::read_config(params.config)?;
        params.overrides.apply(
            &mut config.seed,
            &mut config.adam.learning_rate,
            std::slice::from_mut(&mut config.epochs),
        );
        config.validate()?;
        refuse_overwrite(params.out, params.resume)?;
        let dataset = load(params.data, weft_data::ClothDataset::load)?;
        Ok(Self {
            params,
            config,
            dataset,
        })
    }
}

impl TrainJob for InertialCorrectionMlpJob<'_> {
    fn start(&self) -> Result<Vec<String>> {
        let windows = |split| weft_surrogate::inertial_correction::split_windows(&self.dataset, split);
        Ok(vec![format!(
            "inertial-correction-mlp/{}: {} training and {} validation windows, {} vertices, base {:?}, seed {}",
            self.dataset.name,
            windows("train")?.len(),
            windows("validation")?.len(),
            self.dataset.rest.num_vertices(),
            self.config.base,
            self.config.seed
        )])
    }

    /// Trains, then says the kept epoch and the one-step M_rms of the predictor, the
    /// linear correction and the network on the validation and test frames.
    fn run(self) -> Result<TrainReport> {
        use crate::inertial_correction_mlp::InertialCorrectionMlp;
        let (p, data) = (self.params, &self.dataset);
        let mut progress = TrainProgress::new(p.quiet, &format!("inertial-correction-mlp/{}", data.name))?;
        let (model, state) = InertialCorrectionMlp::train(p.out, data, &self.config, &mut progress)?;
        drop(progress);
        let rms = |v: Vec<f64>| (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt();
        let mut predictor = model.linear().clone();
        predictor.disable_correction();
        let mut lines = vec![format!(
            "inertial-correction-mlp/{}: kept epoch {} of {}",
            data.name, state.best_epoch, state.epochs_done
        )];
        if let Some(v) = model.validation() {
            lines.push(format!(
                "  validation one-step M_rms: {:.3} mm MLP, {:.3} mm linear correction, {:.3} mm inertial predictor",
                v.mlp_mm, v.linear_mm, v.predictor_mm
            ));
        }
        lines.push(format!(
            "  test one-step M_rms: {:.3} mm MLP, {:.3} mm linear correction, {:.3} mm inertial predictor",
            rms(model.one_step_errors(data, "test")?),
            rms(model.linear().one_step_errors(data, "test")?),
            rms(predictor.one_step_errors(data, "test")?)
        ));
        lines.push(format!(
            "  test floor of the {}-component correction basis (each frame's own residual codes): {:.3} mm",
            model.linear().num_codes(),
            rms(model.linear().basis_floor_errors(data, "test")?)
        ));
        Ok(TrainReport::new(lines, p.out))
    }
}

/// The drape flags beside the shared ones.
#[derive(Debug, Clone, Copy)]
pub struct DrapeJobParams<'a> {
    pub layer: DrapeLayerKind,
    /// μ of the quasistatic layer, or where a learned μ starts.
    pub mu: Option<f64>,
    /// Learn μ (`Some(true)`: one per vertex).
    pub learn_mu: Option<bool>,
    /// A drape model directory whose best network weights training starts from.
    pub init: Option<&'a Path>,
    /// The fixed μ the kept network is scored at after training.
    pub scan_mu: &'a [f64],
    /// Train on the first N training examples only.
    pub train_examples: Option<usize>,
}

/// Geng et al.'s pose → cloth network, alone or through a layer.
#[derive(Debug)]
pub struct DrapeJob<'a> {
    params: TrainParams<'a>,
    drape: DrapeJobParams<'a>,
    config: crate::drape::DrapeTrainingSettings,
    layer: crate::drape::Layer,
    epochs: usize,
    run: crate::drape::DrapeRun,
    name: String,
}

impl<'a> DrapeJob<'a> {
    pub fn new(params: TrainParams<'a>, drape: DrapeJobParams<'a>) -> Result<Self> {
        let config = drape_config(params.config, &params.overrides)?;
        let layer = drape_layer(drape.layer, drape.mu, drape.learn_mu, drape.scan_mu)?;
        let epochs = if drape.init.is_some() {
            config.finetune_epochs
        } else {
            config.pretrain_epochs
        };
        refuse_overwrite(params.out, params.resume)?;
        let mut run = load(params.data, |d| crate::drape::DrapeRun::load(d, &config))?;
        if let Some(n) = drape.train_examples {
            check_train_examples(params.data, n, run.train.len())?;
            run.keep_training_prefix(n)?;
        }
        if run.train.is_empty() || run.validation.is_empty() {
            return Err(Error::TooFewExamples {
                data: params.data.display().to_string(),
                train: run.train.len(),
                validation: run.validation.len(),
            });
        }
        let name = params
            .out
            .file_name()
            .map_or("model".into(), |n| n.to_string_lossy().into_owned());
        Ok(Self {
            params,
            drape,
            config,
            layer,
            epochs,
            run,
            name,
        })
    }
}

/// `--train-examples n` keeps a prefix of the `available` training examples: at least one.
fn check_train_examples(data: &Path, n: usize, available: usize) -> Result<()> {
    if n == 0 || n > available {
        return Err(Error::TrainExamples {
            asked: n,
            data: data.display().to_string(),
            available,
        });
    }
    Ok(())
}

impl TrainJob for DrapeJob<'_> {
    fn start(&self) -> Result<Vec<String>> {
        let (run, name, layer, epochs) = (&self.run, &self.name, &self.layer, self.epochs);
        Ok(vec![format!(
            "drape/{name}: {layer}, {} training and {} validation examples on {} vertices, {epochs} epochs",
            run.train.len(),
            run.validation.len(),
            run.num_vertices()
        )])
    }

    fn run(self) -> Result<TrainReport> {
        let (p, name) = (self.params, &self.name);
        let plan = crate::drape::Plan {
            name,
            layer: self.layer,
            init: self.drape.init,
            epochs: self.epochs,
            retrain_on_mismatch: false,
        };
        let mut progress = TrainProgress::new(p.quiet, &format!("drape/{name}"))?;
        let fitted = self.run.fit(p.out, &plan, &self.config, &mut progress)?;
        drop(progress);
        let summary = self.run.summarize(p.out, &fitted, &self.config, self.drape.scan_mu)?;
        Ok(TrainReport::new(summary.lines(name), p.out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn train_examples_keep_at_least_one_and_no_more_than_there_are() {
        let data = Path::new("data/drape");
        check_train_examples(data, 1, 16).unwrap();
        check_train_examples(data, 16, 16).unwrap();
        let e = check_train_examples(data, 17, 16).unwrap_err().to_string();
        assert_eq!(e, "--train-examples 17: data/drape has 16 training examples");
        assert!(matches!(
            check_train_examples(data, 0, 16),
            Err(Error::TrainExamples { asked: 0, .. })
        ));
    }

    #[test]
    fn a_failed_load_names_the_directory_and_keeps_the_cause() {
        use std::error::Error as _;
        let dir = std::env::temp_dir().join(format!("weft-nn-train-job-{}", std::process::id()));
        let e = load(&dir, weft_data::LimbDataset::load).unwrap_err();
        assert_eq!(e.to_string(), format!("loading {}", dir.display()));
        assert!(e.source().is_some());
    }

    #[test]
    fn reports_name_the_model_last() {
        let state = |best_epoch, best_validation| TrainingState {
            config: crate::trainer::TrainerSettings {
                epochs: 3,
                batch: 1,
                seed: 0,
                schedule: Default::default(),
            },
            epochs_done: 3,
            initial_validation: 1.0,
            best_epoch,
            best_validation,
            lr_factor: 1.0,
            epochs_since_best: 0,
            stopped_early: false,
            history: Vec::new(),
        };
        let lines = stage_lines("cloth", &[(1, state(2, 0.5)), (3, state(3, 0.25))]);
        let report = TrainReport::new(lines, Path::new("out/m"));
        assert_eq!(
            report.lines,
            [
                "cloth: stage 1: kept epoch 2 of 3, validation loss 5.0000e-1",
                "cloth: stage 3: kept epoch 3 of 3, validation loss 2.5000e-1",
                "model → out/m",
            ]
        );
    }
}
