//! A learned one-step surrogate for the guarded roll-out (docs/GUARD.md, "A surrogate to
//! guard"): the inertial predictor `2p_{m−1} − p_{m−2}` plus a learned correction.
//!
//! The guard only ever asks for one step from an accepted frame, so what a surrogate
//! must be good at is the one-step error, and the bar is the inertial predictor's — the
//! implicit-Euler solver's own start, whose error is the step's `Δt² a_m`. This model is
//! fitted to exactly that residual,
//!
//! ```text
//! c_m = p_m − (2p_{m−1} − p_{m−2}) = Δt² a_m,       p̂_m = 2p_{m−1} − p_{m−2} + U_c W f_m,
//! ```
//!
//! so it starts from the predictor and can only move away from it where the training
//! data say so: the ridge weight is chosen on the validation frames from a grid that
//! includes "no correction", so a kept model is never worse than the predictor there.
//!
//! - **Features** `f_m`, all known when frame `m` is asked for: the codes of `p_{m−1}`
//!   and of the displacement `p_{m−1} − p_{m−2}` in a PCA basis of the training frames
//!   (the state and `Δt` times the velocity), the controls `q_m` and the grasp's
//!   acceleration `q_m − 2q_{m−1} + q_{m−2}` (what drives the cloth), standardised, and a
//!   bias. `Δt² a = Δt² M⁻¹ f(p, v)`: about a state the force is linear in the
//!   displacement and velocity, which a linear map of their codes represents; gravity
//!   is the bias.
//! - **Output**: codes of `c_m` in a PCA basis `U_c` of the training residuals.
//! - **Range**: each predicted code is clipped to its training range widened by a quarter,
//!   so a state unlike any training frame cannot drive the correction beyond what training
//!   saw (an out-of-range input once moved a frame by 0.33 m before this clip).
//! - **Fit**: linear least squares with a ridge penalty, closed form
//!   ([`weft_linalg::NormalEquations`]): deterministic, no seed.
//!
//! The model directory holds `config.json` (the scene it is tied to, its `Δt` and mesh,
//! the settings, the chosen ridge weight, the validation figures of every candidate, the
//! standardisation and the weights) and `bases.safetensors` (the two PCA bases, f64:
//! geometry, not network weights).

use std::path::Path;

use weft_data::{ClothDataset, is_train_frame, is_validation_frame};

use crate::error::{Error, Result};
use crate::pca::PositionPca;

/// The model kind in `config.json`.
pub const KIND: &str = crate::model_dir::INERTIAL_CORRECTION;

/// How the correction is fitted.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InertialCorrectionSettings {
    /// Components of the positions' PCA whose codes are the state features.
    pub position_components: usize,
    /// Components of the residuals' PCA the correction lives in.
    pub correction_components: usize,
    /// Ridge weights to choose from on validation, relative to the mean diagonal of the
    /// normal matrix `FᵀF` (so the grid means the same on every scene).
    pub ridge: Vec<f64>,
}

impl Default for InertialCorrectionSettings {
    fn default() -> Self {
        Self {
            position_components: 32,
            correction_components: 32,
            ridge: vec![1e-8, 1e-6, 1e-4, 1e-2, 1.0],
        }
    }
}

/// One candidate's one-step error on the validation frames.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RidgeScore {
    /// The relative ridge weight; `None` for no correction (the inertial predictor).
    pub ridge: Option<f64>,
    /// M_rms of the predicted frames (mm).
    pub one_step_mm: f64,
}

/// A fitted inertial correction (see the module docs).
#[derive(Debug, Clone)]
pub struct InertialCorrection {
    meta: Meta,
    positions: PositionPca,
    corrections: PositionPca,
}

/// Everything of a model but its bases: `config.json`.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Meta {
    kind: String,
    scene: String,
    /// Time step (s) of the frames it was fitted on.
    dt: f64,
    num_dofs: usize,
    /// The grasped vertices, in the order of the controls.
    grasp: Vec<usize>,
    settings: InertialCorrectionSettings,
    /// The chosen relative ridge weight; `None` when no correction beat the predictor.
    ridge: Option<f64>,
    validation: Vec<RidgeScore>,
    feature_mean: Vec<f64>,
    feature_scale: Vec<f64>,
    /// `W`, `correction codes × (features + bias)`, row-major.
    weights: Vec<f64>,
    /// Each correction code's range over the training residuals, widened by a quarter on
    /// each side: a prediction is clipped to it, so inputs unlike any training frame cannot
    /// drive the correction beyond what training saw (the guard judges the result either way).
    code_range: Vec<(f64, f64)>,
}

/// The frames a window predicts: `m ≥ 1` with Tan et al.'s split rule (docs/DATASETS.md).
/// Frame 1 is predicted from the initial state held still (`p_{−1} = p_0`), as the guard
/// asks for it.
pub fn windows(data: &ClothDataset, keep: impl Fn(usize) -> bool) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for (s, seq) in data.sequences.iter().enumerate() {
        out.extend((1..seq.num_frames()).filter(|&m| keep(m)).map(|m| (s, m)));
    }
    out
}

/// `(p_{m−2}, p_{m−1})` of window `m` of `seq` (`p_{−1} = p_0`).
pub fn history(seq: &weft_data::ClothSequence, m: usize) -> (&[f64], &[f64]) {
    (seq.frame(m.saturating_sub(2)), seq.frame(m - 1))
}

/// Training windows: frame `m` a training frame and not a validation one (the inputs
/// are true frames of any split, as the guard's are accepted frames).
fn train_windows(data: &ClothDataset) -> Vec<(usize, usize)> {
    windows(data, |m| is_train_frame(m) && !is_validation_frame(m))
}

/// The inertial predictor `2p1 − p2` with the grasped vertices at the controls `q`.
fn inertial(p2: &[f64], p1: &[f64], grasp: &[usize], q: &[f64]) -> Vec<f64> {
    let mut x: Vec<f64> = p1.iter().zip(p2).map(|(a, b)| 2.0 * a - b).collect();
    set_grasp(&mut x, grasp, q);
    x
}

fn set_grasp(x: &mut [f64], grasp: &[usize], q: &[f64]) {
    for (g, &v) in grasp.iter().enumerate() {
        x[3 * v..3 * v + 3].copy_from_slice(&q[3 * g..3 * g + 3]);
    }
}

/// The raw (unstandardised) features of a step, without the bias.
fn raw_features(positions: &PositionPca, p2: &[f64], p1: &[f64], grasp: &[usize], q: &[f64]) -> Vec<f64> {
    let z1 = positions.encode(p1);
    let z2 = positions.encode(p2);
    let mut f: Vec<f64> = z1
        .iter()
        .copied()
        .chain(z1.iter().zip(&z2).map(|(a, b)| a - b))
        .collect();
    f.extend_from_slice(q);
    for (g, &v) in grasp.iter().enumerate() {
        for k in 0..3 {
            f.push(q[3 * g + k] - 2.0 * p1[3 * v + k] + p2[3 * v + k]);
        }
    }
    f
}

/// M_rms of one frame (mm): `1000 · ‖a − b‖ / √(3V)`.
pub fn frame_mm(a: &[f64], b: &[f64]) -> f64 {
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    1e3 * (weft_linalg::dot(&d, &d) / a.len().max(1) as f64).sqrt()
}

impl InertialCorrection {
    /// Fits the correction on `data`'s training frames and chooses the ridge weight on its
    /// validation frames (module docs).
    pub fn fit(data: &ClothDataset, settings: &InertialCorrectionSettings) -> Result<Self> {
        let train = train_windows(data);
        let validation = windows(data, is_validation_frame);
        if train.is_empty() || validation.is_empty() {
            return Err(Error::InvalidParameter {
                name: "dataset",
                value: format!("{} training and {} validation windows", train.len(), validation.len()),
                reason: "fitting the correction needs both (sequences of at least 12 frames)",
            });
        }
        if settings.position_components == 0 || settings.correction_components == 0 {
            return Err(Error::InvalidParameter {
                name: "inertial correction components",
                value: format!(
                    "{} and {}",
                    settings.position_components, settings.correction_components
                ),
                reason: "both bases need at least one component",
            });
        }
        if let Some(r) = settings.ridge.iter().find(|r| !(**r > 0.0 && r.is_finite())) {
            return Err(Error::InvalidParameter {
                name: "ridge weight",
                value: r.to_string(),
                reason: "must be positive and finite",
            });
        }
        let seq = |s: usize| &data.sequences[s];
        let frames: Vec<Vec<f64>> = train.iter().map(|&(s, m)| seq(s).frame(m).to_vec()).collect();
        let positions = PositionPca::fit(&frames, settings.position_components)?;
        let residuals: Vec<Vec<f64>> = train
            .iter()
            .map(|&(s, m)| {
                let (p2, p1) = history(seq(s), m);
                let guess = inertial(p2, p1, &data.grasp, seq(s).control(m));
                seq(s).frame(m).iter().zip(&guess).map(|(a, b)| a - b).collect()
            })
            .collect();
        let corrections = PositionPca::fit(&residuals, settings.correction_components)?;
        let features = |w: &[(usize, usize)]| -> Vec<Vec<f64>> {
            w.iter()
                .map(|&(s, m)| {
                    let (p2, p1) = history(seq(s), m);
                    raw_features(&positions, p2, p1, &data.grasp, seq(s).control(m))
                })
                .collect()
        };
        let raw = features(&train);
        let (feature_mean, feature_scale) = standardisation(&raw);
        let design = design_matrix(&raw, &feature_mean, &feature_scale);
        let k = corrections.num_components();
        let codes: Vec<Vec<f64>> = residuals.iter().map(|c| corrections.encode(c)).collect();
        let code_range = (0..k)
            .map(|j| {
                let (lo, hi) = codes.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), c| {
                    (lo.min(c[j]), hi.max(c[j]))
                });
                (lo - 0.25 * (hi - lo), hi + 0.25 * (hi - lo))
            })
            .collect();
        let targets: Vec<f64> = codes.concat();
        let normal = weft_linalg::NormalEquations::new(&design, &targets, train.len(), feature_mean.len() + 1, k)?;
        let mut model = Self {
            meta: Meta {
                kind: KIND.into(),
                scene: data.scene.name.clone(),
                dt: data.scene.dt,
                num_dofs: 3 * data.rest.num_vertices(),
                grasp: data.grasp.clone(),
                settings: settings.clone(),
                ridge: None,
                validation: Vec::new(),
                feature_mean,
                feature_scale,
                weights: Vec::new(),
                code_range,
            },
            positions,
            corrections,
        };
        model.choose_ridge(data, &normal, &validation)?;
        Ok(model)
    }

    /// Solves the ridge problem for every candidate weight, scores each (and no
    /// correction) on the validation windows, and keeps the best.
    fn choose_ridge(
        &mut self,
        data: &ClothDataset,
        normal: &weft_linalg::NormalEquations,
        validation: &[(usize, usize)],
    ) -> Result<()> {
        let (features, codes) = (normal.features(), normal.outputs());
        let scale = normal.mean_diagonal(features);
        let mut best: (f64, Option<f64>, Vec<f64>) = (self.validation_mm(data, validation)?, None, Vec::new());
        self.meta.validation = vec![RidgeScore {
            ridge: None,
            one_step_mm: best.0,
        }];
        for &r in &self.meta.settings.ridge.clone() {
            // `features × codes` row-major; the model keeps `codes × features`.
            let w = normal.solve(features, r * scale)?;
            self.meta.weights = (0..codes)
                .flat_map(|c| (0..features).map(move |f| (f, c)))
                .map(|(f, c)| w[f * codes + c])
                .collect();
            self.meta.ridge = Some(r);
            let mm = self.validation_mm(data, validation)?;
            self.meta.validation.push(RidgeScore {
                ridge: Some(r),
                one_step_mm: mm,
            });
            if mm < best.0 {
                best = (mm, Some(r), self.meta.weights.clone());
            }
        }
        (self.meta.ridge, self.meta.weights) = (best.1, best.2);
        Ok(())
    }

    /// M_rms (mm) of the one-step predictions over `windows` of `data`.
    fn validation_mm(&self, data: &ClothDataset, windows: &[(usize, usize)]) -> Result<f64> {
        let errors = self.one_step_errors_at(data, windows)?;
        Ok((errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt())
    }

    fn one_step_errors_at(&self, data: &ClothDataset, windows: &[(usize, usize)]) -> Result<Vec<f64>> {
        windows
            .iter()
            .map(|&(s, m)| {
                let seq = &data.sequences[s];
                let (p2, p1) = history(seq, m);
                let x = self.predict(p2, p1, seq.control(m))?;
                Ok(frame_mm(&x, seq.frame(m)))
            })
            .collect()
    }

    /// Each frame's one-step error (M_rms, mm) on `split` of `data` (`train`,
    /// `validation` or `test`, Tan et al.'s frame rule), from the true history: the
    /// figure the guard's acceptance depends on.
    pub fn one_step_errors(&self, data: &ClothDataset, split: &str) -> Result<Vec<f64>> {
        self.check_dataset(data)?;
        self.one_step_errors_at(data, &split_windows(data, split)?)
    }

    /// Each frame's M_rms (mm) on `split` of `data` with the true residual's own codes
    /// `U_cᵀ c_m` (unclipped): the floor of any correction in this basis, whatever maps the
    /// features to the codes.
    pub fn basis_floor_errors(&self, data: &ClothDataset, split: &str) -> Result<Vec<f64>> {
        self.check_dataset(data)?;
        split_windows(data, split)?
            .iter()
            .map(|&(s, m)| {
                let seq = &data.sequences[s];
                let (p2, p1) = history(seq, m);
                let codes = self.residual_codes(p2, p1, seq.control(m), seq.frame(m))?;
                let x = self.with_codes(p2, p1, seq.control(m), &codes)?;
                Ok(frame_mm(&x, seq.frame(m)))
            })
            .collect()
    }

    /// Frame `p_m` (flat positions, m) from `p_{m−2}`, `p_{m−1}` and the controls `q_m`
    /// (3 per grasped vertex, in the model's grasp order).
    pub fn predict(&self, p2: &[f64], p1: &[f64], q: &[f64]) -> Result<Vec<f64>> {
        if self.meta.ridge.is_none() {
            self.check_input(p2, p1, q)?;
            return Ok(inertial(p2, p1, &self.meta.grasp, q));
        }
        let codes = self.linear_codes(&self.features(p2, p1, q)?);
        self.with_codes(p2, p1, q, &codes)
    }

    fn check_input(&self, p2: &[f64], p1: &[f64], q: &[f64]) -> Result<()> {
        let n = self.meta.num_dofs;
        if p2.len() != n || p1.len() != n || q.len() != 3 * self.meta.grasp.len() {
            return Err(Error::Shape {
                what: "inertial correction input",
                expected: format!("two frames of {n} and {} controls", 3 * self.meta.grasp.len()),
                got: format!("{}, {} and {}", p2.len(), p1.len(), q.len()),
            });
        }
        Ok(())
    }

    /// The step's features `f_m` standardised by the training frames' mean and spread,
    /// without the bias (module docs): what `W` multiplies, and the input of the nonlinear
    /// correction built on this model.
    pub fn features(&self, p2: &[f64], p1: &[f64], q: &[f64]) -> Result<Vec<f64>> {
        self.check_input(p2, p1, q)?;
        let raw = raw_features(&self.positions, p2, p1, &self.meta.grasp, q);
        Ok(raw
            .iter()
            .zip(&self.meta.feature_mean)
            .zip(&self.meta.feature_scale)
            .map(|((v, m), s)| (v - m) / s)
            .collect())
    }

    /// The linear correction's codes `W [f; 1]` of standardised features `f`, clipped to the
    /// training range; zeros where no correction was kept (`ridge: None`).
    pub fn linear_codes(&self, features: &[f64]) -> Vec<f64> {
        let k = self.corrections.num_components();
        if self.meta.ridge.is_none() {
            return vec![0.0; k];
        }
        let f: Vec<f64> = features.iter().copied().chain(std::iter::once(1.0)).collect();
        let mut codes: Vec<f64> = self
            .meta
            .weights
            .chunks_exact(f.len())
            .map(|w| w.iter().zip(&f).map(|(a, b)| a * b).sum::<f64>())
            .collect();
        self.clip_codes(&mut codes);
        codes
    }

    /// Clips each correction code to its training range widened by a quarter (module docs).
    pub fn clip_codes(&self, codes: &mut [f64]) {
        for (c, (lo, hi)) in codes.iter_mut().zip(&self.meta.code_range) {
            *c = c.clamp(*lo, *hi);
        }
    }

    /// The inertial predictor plus the correction `U_c codes`, the grasped vertices at the
    /// controls (Eq. G7 with the codes given): checked to be finite.
    pub fn with_codes(&self, p2: &[f64], p1: &[f64], q: &[f64], codes: &[f64]) -> Result<Vec<f64>> {
        self.check_input(p2, p1, q)?;
        let mut x = inertial(p2, p1, &self.meta.grasp, q);
        let c = self.corrections.decode(codes);
        x.iter_mut().zip(&c).for_each(|(a, b)| *a += b);
        set_grasp(&mut x, &self.meta.grasp, q);
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "inertial correction prediction",
                index: i,
            });
        }
        Ok(x)
    }

    /// The codes in `U_c` of the inertial residual `p − (2p1 − p2)` (grasp at `q`): the
    /// targets of a correction fitted in this basis.
    pub fn residual_codes(&self, p2: &[f64], p1: &[f64], q: &[f64], p: &[f64]) -> Result<Vec<f64>> {
        self.check_input(p2, p1, q)?;
        let guess = inertial(p2, p1, &self.meta.grasp, q);
        let c: Vec<f64> = p.iter().zip(&guess).map(|(a, b)| a - b).collect();
        Ok(self.corrections.encode(&c))
    }

    /// Components of the correction basis `U_c` (the codes' length).
    pub fn num_codes(&self) -> usize {
        self.corrections.num_components()
    }

    /// The standardised features' length (without the bias).
    pub fn num_features(&self) -> usize {
        self.meta.feature_mean.len()
    }

    /// The step's controls `q_m` (3 per grasped vertex, in the grasp's order) from the
    /// DOFs the guard prescribes; every grasped DOF must be among them.
    pub fn controls(&self, prescribed: &[(usize, f64)]) -> Result<Vec<f64>> {
        let mut q = vec![f64::NAN; 3 * self.meta.grasp.len()];
        for &(dof, value) in prescribed {
            if let Some(g) = self.meta.grasp.iter().position(|&v| v == dof / 3) {
                q[3 * g + dof % 3] = value;
            }
        }
        if let Some(i) = q.iter().position(|v| v.is_nan()) {
            return Err(Error::InvalidParameter {
                name: "controls",
                value: format!(
                    "grasped vertex {} has no prescribed DOF {}",
                    self.meta.grasp[i / 3],
                    i % 3
                ),
                reason: "the correction was fitted with every grasped DOF prescribed",
            });
        }
        Ok(q)
    }

    /// Drops the correction: the model then proposes the inertial predictor's frame (the
    /// baseline it is compared with, on the same code path).
    pub fn disable_correction(&mut self) {
        self.meta.ridge = None;
    }

    /// The relative ridge weight chosen on validation; `None` when no correction beat the
    /// inertial predictor there (the model then is the predictor).
    pub fn ridge(&self) -> Option<f64> {
        self.meta.ridge
    }

    /// Every candidate's validation one-step error, "no correction" first.
    pub fn validation_scores(&self) -> &[RidgeScore] {
        &self.meta.validation
    }

    pub fn scene(&self) -> &str {
        &self.meta.scene
    }

    /// The time step (s) of the frames it was fitted on.
    pub fn dt(&self) -> f64 {
        self.meta.dt
    }

    /// The DOF count of the mesh it was fitted on.
    pub fn num_dofs(&self) -> usize {
        self.meta.num_dofs
    }

    /// Refuses a dataset of another scene, mesh or grasp.
    pub fn check_dataset(&self, data: &ClothDataset) -> Result<()> {
        let n = 3 * data.rest.num_vertices();
        if n != self.meta.num_dofs || data.grasp != self.meta.grasp || data.scene.name != self.meta.scene {
            return Err(Error::Shape {
                what: "dataset for the inertial correction",
                expected: format!("scene {} with {} DOFs", self.meta.scene, self.meta.num_dofs),
                got: format!("scene {} with {n} DOFs", data.scene.name),
            });
        }
        Ok(())
    }

    /// Writes the model directory `dir` (module docs).
    pub fn save(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::Io {
            path: dir.display().to_string(),
            source: e,
        })?;
        let mut arrays = self.positions.to_arrays("positions");
        arrays.extend(self.corrections.to_arrays("corrections"));
        weft_data::files::write_safetensors(&dir.join("bases.safetensors"), &arrays, Default::default())?;
        Ok(weft_data::files::write_json(&dir.join("config.json"), &self.meta)?)
    }

    /// Reads a model directory written by [`InertialCorrection::save`].
    pub fn load(dir: &Path) -> Result<Self> {
        crate::model_dir::check_model_kind(dir, KIND)?;
        let meta: Meta = crate::model_dir::read_json(&dir.join("config.json"))?;
        let arrays = crate::model_dir::read_f64_arrays(&dir.join("bases.safetensors"))?;
        let path = dir.display().to_string();
        let positions = PositionPca::from_arrays(&arrays, "positions", &path)?;
        let corrections = PositionPca::from_arrays(&arrays, "corrections", &path)?;
        let features = 2 * positions.num_components() + 6 * meta.grasp.len();
        if meta.feature_mean.len() != features
            || meta.feature_scale.len() != features
            || (meta.ridge.is_some() && meta.weights.len() != corrections.num_components() * (features + 1))
            || meta.code_range.len() != corrections.num_components()
            || positions.dim() != meta.num_dofs
            || corrections.dim() != meta.num_dofs
        {
            return Err(Error::Checkpoint {
                path,
                reason: "the weights, standardisation and bases do not fit together".into(),
            });
        }
        Ok(Self {
            meta,
            positions,
            corrections,
        })
    }
}

/// `cargo xtask train inertial-correction`: fits the correction on the cloth dataset in
/// `data` (settings from the JSON file `config`, else the defaults) and writes the model
/// directory `out`, which must not hold a model yet. Returns the lines to print: the chosen
/// ridge weight, every candidate's validation error and the test one-step errors beside
/// the inertial predictor's.
pub fn fit_directory(data: &Path, out: &Path, config: Option<&Path>) -> Result<Vec<String>> {
    if out.join("config.json").exists() {
        return Err(Error::Checkpoint {
            path: out.display().to_string(),
            reason: "already holds a model; choose another --out or remove it".into(),
        });
    }
    let settings: InertialCorrectionSettings = match config {
        Some(c) => crate::model_dir::read_json(c)?,
        None => InertialCorrectionSettings::default(),
    };
    let dataset = ClothDataset::load(data)?;
    let clock = std::time::Instant::now();
    let model = InertialCorrection::fit(&dataset, &settings)?;
    model.save(out)?;
    let mut inertial = model.clone();
    inertial.disable_correction();
    let rms = |v: Vec<f64>| (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let mut lines = vec![format!(
        "{}: inertial correction fitted in {:.1} s on {} sequences; ridge {} (chosen on validation) → {}",
        dataset.name,
        clock.elapsed().as_secs_f64(),
        dataset.sequences.len(),
        model
            .ridge()
            .map_or("none: no correction beat the inertial predictor".into(), |r| format!(
                "{r:e}"
            )),
        out.display()
    )];
    for s in model.validation_scores() {
        let name = s.ridge.map_or("no correction".into(), |r| format!("ridge {r:e}"));
        lines.push(format!("  validation one-step M_rms, {name}: {:.3} mm", s.one_step_mm));
    }
    lines.push(format!(
        "  test one-step M_rms: {:.3} mm corrected, {:.3} mm inertial predictor",
        rms(model.one_step_errors(&dataset, "test")?),
        rms(inertial.one_step_errors(&dataset, "test")?)
    ));
    Ok(lines)
}

/// The surrogate stored in the model directory `dir`, for weft-sim's guard: the inertial
/// correction is the one model kind without a network that proposes frames under the
/// guard (weft-nn's loader adds its nonlinear version); a directory of another kind (the embedding, NNWarp, the limb or drape models) is refused
/// by name rather than misread.
pub fn load_surrogate(dir: &Path) -> Result<Box<dyn weft_sim::guard::Surrogate>> {
    let config: serde_json::Value = crate::model_dir::read_json(&dir.join("config.json"))?;
    match crate::model_dir::stored_model_kind(&config) {
        Some(KIND) => Ok(Box::new(InertialCorrection::load(dir)?)),
        Some(mlp @ crate::model_dir::INERTIAL_CORRECTION_MLP) => Err(Error::Checkpoint {
            path: dir.display().to_string(),
            reason: format!(
                "holds a `{mlp}` model, a network this crate cannot run: load it with \
                 `weft_nn::inertial_correction_mlp::load_surrogate` (what `cargo xtask simulate --surrogate` does)"
            ),
        }),
        other => Err(Error::Checkpoint {
            path: dir.display().to_string(),
            reason: format!(
                "holds {}, not a surrogate the guard can step (`{KIND}`: `cargo xtask train {KIND}`)",
                other.map_or_else(|| "no model weft knows".to_string(), |k| format!("a `{k}` model"))
            ),
        }),
    }
}

/// The windows `(sequence, frame)` of `split` (`train`, `validation` or `test`; module
/// docs): what every one-step figure of this model and of the nonlinear correction built on
/// it (weft-nn's `inertial_correction_mlp`) is measured on.
pub fn split_windows(data: &ClothDataset, split: &str) -> Result<Vec<(usize, usize)>> {
    Ok(match split {
        "train" => train_windows(data),
        "validation" => windows(data, is_validation_frame),
        "test" => windows(data, |m| !is_train_frame(m)),
        _ => {
            return Err(Error::InvalidParameter {
                name: "split",
                value: split.into(),
                reason: "one of train, validation, test",
            });
        }
    })
}

/// Per-feature mean and standard deviation over the training rows (a constant feature
/// gets scale 1, so standardising never divides by zero).
fn standardisation(raw: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let n = raw.len() as f64;
    let k = raw[0].len();
    let mean: Vec<f64> = (0..k).map(|j| raw.iter().map(|r| r[j]).sum::<f64>() / n).collect();
    let scale = (0..k)
        .map(|j| {
            let sd = (raw.iter().map(|r| (r[j] - mean[j]).powi(2)).sum::<f64>() / n).sqrt();
            if sd > 1e-12 * (1.0 + mean[j].abs()) { sd } else { 1.0 }
        })
        .collect();
    (mean, scale)
}

/// The standardised features with a bias column, row-major.
fn design_matrix(raw: &[Vec<f64>], mean: &[f64], scale: &[f64]) -> Vec<f64> {
    raw.iter()
        .flat_map(|r| {
            r.iter()
                .zip(mean)
                .zip(scale)
                .map(|((v, m), s)| (v - m) / s)
                .chain(std::iter::once(1.0))
        })
        .collect()
}

impl weft_sim::guard::Surrogate for InertialCorrection {
    fn name(&self) -> &str {
        KIND
    }
    fn num_dofs(&self) -> usize {
        self.meta.num_dofs
    }
    fn scene(&self) -> Option<&str> {
        Some(&self.meta.scene)
    }
    fn dt(&self) -> Option<f64> {
        Some(self.meta.dt)
    }
    fn propose(
        &mut self,
        input: &weft_sim::guard::StepInput<'_>,
    ) -> std::result::Result<Vec<f64>, weft_sim::guard::SurrogateError> {
        let q = self.controls(input.prescribed)?;
        Ok(self.predict(input.previous, input.current, &q)?)
    }
}
