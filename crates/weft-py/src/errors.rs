//! The crates' typed errors as Python exceptions: bad input (shapes, non-finite values,
//! out-of-range parameters, degenerate rest meshes) is a `ValueError`, files an `OSError`,
//! and a solve that did not reach its answer a `weft.SolverError` whose second argument is
//! the solver's report (a dict; the Python package exposes it as `.report`).

use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

pyo3::create_exception!(
    weft,
    SolverError,
    PyRuntimeError,
    "A solve did not reach its answer; `.report` holds what the solver reported."
);

/// A JSON value as the Python object `json.loads` would give.
pub fn json_to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any(),
        Value::Number(n) => match (n.as_i64(), n.as_f64()) {
            (Some(i), _) => i.into_pyobject(py)?.into_any(),
            (None, Some(f)) => f.into_pyobject(py)?.into_any(),
            _ => n.to_string().into_pyobject(py)?.into_any(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(a) => {
            let list = PyList::empty(py);
            for x in a {
                list.append(json_to_py(py, x)?)?;
            }
            list.into_any()
        }
        Value::Object(o) => {
            let dict = PyDict::new(py);
            for (k, x) in o {
                dict.set_item(k, json_to_py(py, x)?)?;
            }
            dict.into_any()
        }
    })
}

/// `weft.SolverError(message, report)`.
pub fn solver_error(message: String, report: serde_json::Value) -> PyErr {
    Python::attach(|py| match json_to_py(py, &report) {
        Ok(r) => SolverError::new_err((message, r.unbind())),
        Err(e) => e,
    })
}

/// Prefixes an error's message with the batch example it came from.
pub fn in_example(e: PyErr, b: usize) -> PyErr {
    Python::attach(|py| {
        let message = format!("example {b}: {}", e.value(py));
        if e.is_instance_of::<SolverError>(py) {
            let report = e
                .value(py)
                .getattr("args")
                .and_then(|a| a.get_item(1))
                .map(Bound::unbind)
                .unwrap_or_else(|_| py.None());
            SolverError::new_err((message, report))
        } else if e.is_instance_of::<PyOSError>(py) {
            PyOSError::new_err(message)
        } else {
            PyValueError::new_err(message)
        }
    })
}

pub fn proj(e: weft_proj::Error) -> PyErr {
    use weft_proj::Error as E;
    let message = e.to_string();
    match e {
        E::SolverFailed { status, iterations } => solver_error(
            message,
            serde_json::json!({"kind": "solver-failed", "status": status, "iterations": iterations}),
        ),
        E::SolverSetup(_) => solver_error(message, serde_json::json!({"kind": "solver-setup"})),
        E::ConstraintViolated { edge, ratio, bound } => solver_error(
            message,
            serde_json::json!({"kind": "constraint-violated", "edge": edge, "ratio": ratio, "bound": bound}),
        ),
        E::NonFiniteOutput { what, index } => solver_error(
            message,
            serde_json::json!({"kind": "non-finite-output", "what": what, "index": index}),
        ),
        E::CollapsedSprings { count, first } => solver_error(
            message,
            serde_json::json!({"kind": "collapsed-springs", "count": count, "first": first}),
        ),
        E::NotAMinimum { shifts } => {
            solver_error(message, serde_json::json!({"kind": "not-a-minimum", "shifts": shifts}))
        }
        E::Sim(s) => sim(s),
        E::Linalg(_) => solver_error(message, serde_json::json!({"kind": "linear-algebra"})),
        // Bad input: lengths, non-finite values, parameters, degenerate rest meshes.
        _ => PyValueError::new_err(message),
    }
}

pub fn sim(e: weft_sim::Error) -> PyErr {
    let message = e.to_string();
    match e {
        weft_sim::Error::Mesh(m) => mesh(m),
        weft_sim::Error::NotConverged { .. }
        | weft_sim::Error::WarpNotSettled { .. }
        | weft_sim::Error::NonFinite { .. }
        | weft_sim::Error::Linalg(_) => solver_error(message, serde_json::json!({"kind": "simulation"})),
        _ => PyValueError::new_err(message),
    }
}

pub fn mesh(e: weft_mesh::Error) -> PyErr {
    let message = e.to_string();
    match e {
        weft_mesh::Error::Io { .. } => PyOSError::new_err(message),
        _ => PyValueError::new_err(message),
    }
}

pub fn acap(e: weft_acap::Error) -> PyErr {
    PyValueError::new_err(e.to_string())
}

pub fn data(e: weft_data::Error) -> PyErr {
    let message = e.to_string();
    match e {
        weft_data::Error::Io { .. } => PyOSError::new_err(message),
        weft_data::Error::Sim(s) => sim(s),
        _ => PyValueError::new_err(message),
    }
}

/// A surrogate's fit, model directory or kind: files are `OSError`s, everything else
/// (bad settings, a model of another kind, parts that do not fit) a `ValueError`.
pub fn surrogate(e: weft_surrogate::Error) -> PyErr {
    let message = e.to_string();
    match e {
        weft_surrogate::Error::Io { .. } => PyOSError::new_err(message),
        weft_surrogate::Error::Data(d) => data(d),
        _ => PyValueError::new_err(message),
    }
}
