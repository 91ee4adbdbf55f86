//! Geng et al.'s projection layers on numpy batches: forward solves in parallel (rayon,
//! GIL released), backward passes from the solutions the forward call returned, and
//! per-example warm starts keyed by the caller's example ids, as weft-nn's candle ops
//! keep them. A batch is all or nothing: on any example's error nothing is remembered.

use std::sync::Arc;

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use weft_proj::quasistatic::QuasistaticSolution;
use weft_proj::{
    InextensibilityLayer, QuasistaticLayer, QuasistaticParams, SocpSettings, SocpSolution, WarmStarts,
    ZeroLengthScaling,
};

use crate::arrays;
use crate::errors::{self, in_example, json_to_py};

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Inextensibility>()?;
    m.add_class::<Quasistatic>()?;
    m.add_class::<SocpBatch>()?;
    m.add_class::<QuasistaticBatch>()?;
    Ok(())
}

/// `keys` checked to name each example of a batch of `b` once.
fn check_keys(keys: &Option<Vec<i64>>, b: usize) -> PyResult<()> {
    if let Some(k) = keys {
        if k.len() != b {
            return Err(PyValueError::new_err(format!(
                "keys: one per example expected ({b}), got {}",
                k.len()
            )));
        }
        let mut seen = std::collections::HashSet::new();
        if let Some(dup) = k.iter().find(|x| !seen.insert(**x)) {
            return Err(PyValueError::new_err(format!(
                "keys: example key {dup} appears twice in one batch"
            )));
        }
    }
    Ok(())
}

/// Each example's result, or the first error named by its example.
fn all_or_first_error<T>(results: Vec<Result<T, weft_proj::Error>>) -> PyResult<Vec<T>> {
    results
        .into_iter()
        .enumerate()
        .map(|(b, r)| r.map_err(|e| in_example(errors::proj(e), b)))
        .collect()
}

/// `grad_output` as one flat gradient per example of a forward call of `examples`.
fn gradients(grad_output: &PyReadonlyArray3<'_, f64>, vertices: usize, examples: usize) -> PyResult<Vec<Vec<f64>>> {
    let grads = arrays::batch("grad_output", grad_output, vertices)?;
    if grads.len() != examples {
        return Err(PyValueError::new_err(format!(
            "grad_output: {} examples for a forward call of {examples}",
            grads.len()
        )));
    }
    Ok(grads)
}

/// Each example's report as a dict, and the solutions.
fn split_reports<'py, S, R: serde::Serialize>(
    py: Python<'py>,
    solved: Vec<(S, R)>,
) -> PyResult<(Vec<S>, Vec<Bound<'py, PyAny>>)> {
    let mut reports = Vec::with_capacity(solved.len());
    let mut solutions = Vec::with_capacity(solved.len());
    for (s, r) in solved {
        reports.push(json_to_py(py, &serde_json::to_value(&r).unwrap_or_default())?);
        solutions.push(s);
    }
    Ok((solutions, reports))
}

/// The inextensibility projection (Geng et al. §3–4): the mass-weighted closest
/// configuration whose edges are at most `(1 + eps)` times their rest length.
#[pyclass(module = "weft._native", frozen)]
#[derive(Debug)]
pub struct Inextensibility {
    layer: Arc<InextensibilityLayer>,
    warm: WarmStarts<i64, SocpSolution>,
}

/// The solutions of one forward call, for its backward call (opaque).
#[pyclass(module = "weft._native", frozen)]
#[derive(Debug)]
pub struct SocpBatch {
    solutions: Vec<SocpSolution>,
}

#[pymethods]
impl SocpBatch {
    fn __len__(&self) -> usize {
        self.solutions.len()
    }
}

#[pymethods]
impl Inextensibility {
    #[new]
    #[pyo3(signature = (rest_vertices, faces, eps, tolerance = 1e-8, max_iterations = 100))]
    fn new(
        rest_vertices: PyReadonlyArray2<'_, f64>,
        faces: PyReadonlyArray2<'_, i64>,
        eps: f64,
        tolerance: f64,
        max_iterations: u32,
    ) -> PyResult<Self> {
        let rest = arrays::trimesh(&rest_vertices, &faces)?;
        let settings = SocpSettings {
            tolerance,
            max_iterations,
            ..SocpSettings::default()
        };
        let layer = InextensibilityLayer::new(&rest, eps, settings).map_err(errors::proj)?;
        Ok(Self {
            layer: Arc::new(layer),
            warm: WarmStarts::default(),
        })
    }

    #[getter]
    fn num_vertices(&self) -> usize {
        self.layer.num_vertices()
    }

    #[getter]
    fn num_constraints(&self) -> usize {
        self.layer.num_constraints()
    }

    #[getter]
    fn eps(&self) -> f64 {
        self.layer.epsilon()
    }

    /// The objective's per-vertex weights `k_i` (lumped masses over their mean): the
    /// projection minimises `Σ k_i |x_i − x̂_i|²`.
    #[getter]
    fn weights<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<f64>> {
        self.layer.weights().to_vec().into_pyarray(py)
    }

    /// The constrained edges `[E, 2]` (int64) and their rest lengths `[E]` (m): edge `e`
    /// may be at most `(1 + eps) · rest_lengths[e]` long.
    #[getter]
    fn edges<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<i64>>> {
        arrays::to_indices(py, self.layer.rest().edges())
    }

    #[getter]
    fn rest_lengths<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<f64>> {
        self.layer.rest().rest_lengths().to_vec().into_pyarray(py)
    }

    /// Projects predictions `[B, V, 3]`; returns `(positions [B, V, 3], state, reports)`,
    /// `state` being what [`Inextensibility::backward`] needs. With `keys`, example `b`
    /// starts from the solution last found for `keys[b]` and is remembered under it.
    #[pyo3(signature = (predictions, keys = None))]
    fn forward<'py>(
        &self,
        py: Python<'py>,
        predictions: PyReadonlyArray3<'py, f64>,
        keys: Option<Vec<i64>>,
    ) -> PyResult<(Bound<'py, PyArray3<f64>>, SocpBatch, Vec<Bound<'py, PyAny>>)> {
        let v = self.layer.num_vertices();
        let preds = arrays::batch("predictions", &predictions, v)?;
        check_keys(&keys, preds.len())?;
        let starts = self.warm.starts(keys.as_deref(), preds.len());
        let layer = Arc::clone(&self.layer);
        let results = py.detach(move || {
            let previous: Vec<Option<&SocpSolution>> = starts.iter().map(Option::as_ref).collect();
            layer.forward_batch_from(&preds, &previous)
        });
        let solved = all_or_first_error(results)?;
        self.warm
            .remember(keys.as_deref(), solved.iter().map(|(s, _)| s.warm_start()));
        let (solutions, reports) = split_reports(py, solved)?;
        let positions = solutions.iter().map(|s| s.positions().to_vec()).collect();
        Ok((arrays::to_batch(py, positions, v)?, SocpBatch { solutions }, reports))
    }

    /// `∂E/∂r̂` `[B, V, 3]` from `∂E/∂r*` `[B, V, 3]` and a forward call's `state`.
    fn backward<'py>(
        &self,
        py: Python<'py>,
        state: &SocpBatch,
        grad_output: PyReadonlyArray3<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let v = self.layer.num_vertices();
        let grads = gradients(&grad_output, v, state.solutions.len())?;
        let layer = Arc::clone(&self.layer);
        let solutions = &state.solutions;
        let out = py
            .detach(|| layer.backward_batch(solutions, &grads))
            .map_err(errors::proj)?;
        arrays::to_batch(py, out, v)
    }

    /// The example keys with a remembered solution, sorted.
    fn warm_keys(&self) -> Vec<i64> {
        self.warm.keys()
    }

    /// Forgets every example's warm start.
    fn clear_warm_starts(&self) {
        self.warm.clear()
    }
}

/// The quasistatic projection (Geng et al. §5–6): the equilibrium of edge, bending and
/// axial springs tied to the prediction by zero-length springs of scale μ.
#[pyclass(module = "weft._native", frozen)]
#[derive(Debug)]
pub struct Quasistatic {
    layer: Arc<QuasistaticLayer>,
    warm: WarmStarts<i64, Vec<f64>>,
}

/// The solutions of one forward call, for its backward call (opaque).
#[pyclass(module = "weft._native", frozen)]
#[derive(Debug)]
pub struct QuasistaticBatch {
    solutions: Vec<QuasistaticSolution>,
}

#[pymethods]
impl QuasistaticBatch {
    fn __len__(&self) -> usize {
        self.solutions.len()
    }
}

impl Quasistatic {
    /// μ as one float (global) or a float64 `[V]` array (per vertex).
    fn scaling(&self, mu: &Bound<'_, PyAny>) -> PyResult<ZeroLengthScaling> {
        if let Ok(m) = mu.extract::<f64>() {
            return Ok(ZeroLengthScaling::Global(m));
        }
        let a: PyReadonlyArray1<'_, f64> = mu
            .extract()
            .map_err(|_| PyValueError::new_err("mu: expected a float or a float64 array of shape [V]"))?;
        let values = a.as_array().to_vec();
        if values.len() != self.layer.num_vertices() {
            return Err(PyValueError::new_err(format!(
                "mu: expected a float or shape [{}], got [{}]",
                self.layer.num_vertices(),
                values.len()
            )));
        }
        Ok(ZeroLengthScaling::PerVertex(values))
    }
}

#[pymethods]
impl Quasistatic {
    #[new]
    #[pyo3(signature = (
        rest_vertices, faces, stretch_stiffness = 1.0, bend_stiffness = 0.1, axial_stiffness = 0.1,
        zero_length_stiffness = 1.0, tolerance = 1e-8, max_iterations = 100
    ))]
    fn new(
        rest_vertices: PyReadonlyArray2<'_, f64>,
        faces: PyReadonlyArray2<'_, i64>,
        stretch_stiffness: f64,
        bend_stiffness: f64,
        axial_stiffness: f64,
        zero_length_stiffness: f64,
        tolerance: f64,
        max_iterations: usize,
    ) -> PyResult<Self> {
        let rest = arrays::trimesh(&rest_vertices, &faces)?;
        let params = QuasistaticParams {
            stretch_stiffness,
            bend_stiffness,
            axial_stiffness,
            zero_length_stiffness,
            tolerance,
            max_iterations,
            ..QuasistaticParams::default()
        };
        let layer = QuasistaticLayer::new(&rest, params).map_err(errors::proj)?;
        Ok(Self {
            layer: Arc::new(layer),
            warm: WarmStarts::default(),
        })
    }

    #[getter]
    fn num_vertices(&self) -> usize {
        self.layer.num_vertices()
    }

    /// Equilibria of predictions `[B, V, 3]` under μ (a float or `[V]`); returns
    /// `(positions [B, V, 3], state, reports)`. With `keys`, Newton starts example `b` from
    /// the equilibrium last found for `keys[b]`.
    #[pyo3(signature = (predictions, mu, keys = None))]
    fn forward<'py>(
        &self,
        py: Python<'py>,
        predictions: PyReadonlyArray3<'py, f64>,
        mu: &Bound<'py, PyAny>,
        keys: Option<Vec<i64>>,
    ) -> PyResult<(Bound<'py, PyArray3<f64>>, QuasistaticBatch, Vec<Bound<'py, PyAny>>)> {
        let v = self.layer.num_vertices();
        let preds = arrays::batch("predictions", &predictions, v)?;
        check_keys(&keys, preds.len())?;
        let scaling = self.scaling(mu)?;
        let starts = self.warm.starts(keys.as_deref(), preds.len());
        let layer = Arc::clone(&self.layer);
        let results = py.detach(move || layer.forward_batch_from(&preds, &scaling, &starts));
        let solved = all_or_first_error(results)?;
        self.warm
            .remember(keys.as_deref(), solved.iter().map(|(s, _)| s.positions().to_vec()));
        let (solutions, reports) = split_reports(py, solved)?;
        let positions = solutions.iter().map(|s| s.positions().to_vec()).collect();
        Ok((
            arrays::to_batch(py, positions, v)?,
            QuasistaticBatch { solutions },
            reports,
        ))
    }

    /// `(∂E/∂r̂ [B, V, 3], ∂E/∂μ_i [B, V])` from `∂E/∂r*` `[B, V, 3]` and a forward call's
    /// `state`; a global μ's gradient is the sum of the per-vertex one.
    fn backward<'py>(
        &self,
        py: Python<'py>,
        state: &QuasistaticBatch,
        grad_output: PyReadonlyArray3<'py, f64>,
    ) -> PyResult<(Bound<'py, PyArray3<f64>>, Bound<'py, PyArray2<f64>>)> {
        let v = self.layer.num_vertices();
        let grads = gradients(&grad_output, v, state.solutions.len())?;
        let layer = Arc::clone(&self.layer);
        let solutions = &state.solutions;
        let out = py
            .detach(|| layer.backward_batch(solutions, &grads))
            .map_err(errors::proj)?;
        let b = out.len();
        let mu: Vec<f64> = out.iter().flat_map(|g| g.mu_per_vertex.iter().copied()).collect();
        let pred = out.into_iter().map(|g| g.pred).collect();
        let mu = Array2::from_shape_vec((b, v), mu).map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok((arrays::to_batch(py, pred, v)?, mu.into_pyarray(py)))
    }

    /// The example keys with a remembered equilibrium, sorted.
    fn warm_keys(&self) -> Vec<i64> {
        self.warm.keys()
    }

    /// Forgets every example's warm start.
    fn clear_warm_starts(&self) {
        self.warm.clear()
    }
}
