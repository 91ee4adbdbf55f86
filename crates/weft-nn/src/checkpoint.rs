//! Checkpoints: a model's parameters, its optimiser state and a JSON record of where
//! training stands, in one directory, written atomically.
//!
//! Layout of a checkpoint directory:
//! - `params.safetensors`: every parameter under its name (f32);
//! - `optimizer.safetensors`: Adam's moments, `adam.m/<name>` and `adam.v/<name>`;
//! - `state.json`: `{ "adam_steps": n, "extra": … }`, where `extra` is the caller's own
//!   record (stage, epoch, configuration, data fingerprint).
//!
//! Each file is written under a temporary name and renamed into place, `state.json`
//! last, so an interrupted save leaves the previous checkpoint readable.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use candle_core::Tensor;

use crate::adam::Adam;
use crate::error::{Error, Result};
use crate::params::ParamStore;

#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct State {
    adam_steps: u64,
    extra: serde_json::Value,
}

fn io_error(path: &Path, source: std::io::Error) -> Error {
    Error::Io {
        path: path.display().to_string(),
        source,
    }
}

fn write_safetensors(path: &Path, tensors: BTreeMap<String, Tensor>) -> Result<()> {
    let tmp = path.with_extension("safetensors.partial");
    let map: HashMap<String, Tensor> = tensors.into_iter().collect();
    candle_core::safetensors::save(&map, &tmp)?;
    std::fs::rename(&tmp, path).map_err(|e| io_error(path, e))
}

fn read_safetensors(path: &Path, params: &ParamStore) -> Result<BTreeMap<String, Tensor>> {
    read_safetensors_on(path, params.device())
}

fn read_safetensors_on(path: &Path, device: &candle_core::Device) -> Result<BTreeMap<String, Tensor>> {
    if !path.exists() {
        return Err(Error::Checkpoint {
            path: path.display().to_string(),
            reason: "file missing".into(),
        });
    }
    Ok(candle_core::safetensors::load(path, device)
        .map_err(|e| Error::Checkpoint {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?
        .into_iter()
        .collect())
}

/// Saves `params`, `adam` and the caller's `extra` record into `dir` (created if needed).
pub fn save(dir: &Path, params: &ParamStore, adam: &Adam, extra: &serde_json::Value) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| io_error(dir, e))?;
    write_safetensors(&dir.join("params.safetensors"), params.tensors())?;
    let (moments, adam_steps) = adam.state(params.device())?;
    write_safetensors(&dir.join("optimizer.safetensors"), moments)?;
    let state = State {
        adam_steps,
        extra: extra.clone(),
    };
    let path = dir.join("state.json");
    let tmp = dir.join("state.json.partial");
    let text = serde_json::to_string_pretty(&state).expect("plain data serialises");
    std::fs::write(&tmp, text).map_err(|e| io_error(&tmp, e))?;
    std::fs::rename(&tmp, &path).map_err(|e| io_error(&path, e))
}

/// Whether `dir` holds a complete checkpoint.
pub fn exists(dir: &Path) -> bool {
    ["params.safetensors", "optimizer.safetensors", "state.json"]
        .iter()
        .all(|f| dir.join(f).is_file())
}

/// Restores `params` and `adam` from `dir` and returns the caller's `extra` record. The
/// checkpoint must hold exactly this model's parameters with the same shapes.
pub fn load(dir: &Path, params: &ParamStore, adam: &mut Adam) -> Result<serde_json::Value> {
    let path = dir.join("state.json");
    let text = std::fs::read_to_string(&path).map_err(|e| io_error(&path, e))?;
    let state: State = serde_json::from_str(&text).map_err(|e| Error::Checkpoint {
        path: path.display().to_string(),
        reason: e.to_string(),
    })?;
    let p = dir.join("params.safetensors");
    params.assign(&read_safetensors(&p, params)?, &p.display().to_string())?;
    let o = dir.join("optimizer.safetensors");
    adam.restore(
        &read_safetensors(&o, params)?,
        state.adam_steps,
        &o.display().to_string(),
    )?;
    Ok(state.extra)
}

/// Restores only the parameters (inference).
pub fn load_params(dir: &Path, params: &ParamStore) -> Result<()> {
    let p = dir.join("params.safetensors");
    params.assign(&read_safetensors(&p, params)?, &p.display().to_string())
}

/// Writes `value` as pretty JSON to `path` through a temporary name (a model directory's
/// configuration and fitted normalisations).
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let tmp = path.with_extension("json.partial");
    let text = serde_json::to_string_pretty(value).expect("plain data serialises");
    std::fs::write(&tmp, text).map_err(|e| io_error(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| io_error(path, e))
}

/// Reads a JSON file of a model directory; a file that does not parse is a checkpoint
/// error naming it (weft-surrogate's reader, the one for every model directory).
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    Ok(weft_surrogate::model_dir::read_json(path)?)
}

pub use weft_surrogate::model_dir::{check_model_kind, stored_model_kind};

/// Refuses to continue a model directory trained under another configuration:
/// `continues` says whether the stored one (`path`) trains like the asked one but for its
/// epochs — every `train_model` driver asks this before touching the directory. The error
/// names each field in which `stored` and `asked` differ, with both values.
pub fn check_continues<T: serde::Serialize>(path: &Path, continues: bool, stored: &T, asked: &T) -> Result<()> {
    if continues {
        return Ok(());
    }
    let (stored, asked) = (serde_json::to_value(stored), serde_json::to_value(asked));
    let differences = match (stored, asked) {
        (Ok(a), Ok(b)) => {
            let mut out = Vec::new();
            json_differences("", &a, &b, &mut out);
            out
        }
        _ => Vec::new(),
    };
    let what = if differences.is_empty() {
        String::new()
    } else {
        format!(" ({}; stored vs asked)", differences.join("; "))
    };
    Err(Error::Checkpoint {
        path: path.display().to_string(),
        reason: format!(
            "the model was trained under another configuration{what}; continue it with the same one (only the \
             epochs may change)"
        ),
    })
}

/// The fields in which two JSON values differ, as `path: a vs b`, descending into objects.
fn json_differences(path: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
    use serde_json::Value;
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            keys.sort();
            keys.dedup();
            for k in keys {
                let sub = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                let missing = Value::String("(absent)".into());
                json_differences(&sub, x.get(k).unwrap_or(&missing), y.get(k).unwrap_or(&missing), out);
            }
        }
        _ if a != b => out.push(format!("{path}: {a} vs {b}")),
        _ => {}
    }
}
