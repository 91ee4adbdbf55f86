//! Model directories as this crate stores them — `config.json` and f64 arrays in a
//! safetensors file — and the one test of which kind of weft model a directory holds, here
//! because this is the lowest crate that must tell them apart (the guard's loader refuses a
//! directory of another kind by name; weft-nn's loaders ask the same question).

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::{Error, Result};

/// Reads a JSON file of a model directory; a file that does not parse is a checkpoint
/// error naming it.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
        path: path.display().to_string(),
        source: e,
    })?;
    serde_json::from_str(&text).map_err(|e| Error::Checkpoint {
        path: path.display().to_string(),
        reason: e.to_string(),
    })
}

/// Reads every array of a safetensors file as f64 (the file must hold f64 arrays only:
/// this crate stores geometry, not network weights).
pub fn read_f64_arrays(path: &Path) -> Result<BTreeMap<String, Vec<f64>>> {
    let checkpoint = |reason: String| Error::Checkpoint {
        path: path.display().to_string(),
        reason,
    };
    let bytes = std::fs::read(path).map_err(|e| checkpoint(format!("file unreadable: {e}")))?;
    let file = safetensors::SafeTensors::deserialize(&bytes).map_err(|e| checkpoint(e.to_string()))?;
    file.tensors()
        .into_iter()
        .map(|(name, view)| {
            if view.dtype() != safetensors::Dtype::F64 {
                return Err(checkpoint(format!("array {name} is {:?}, not F64", view.dtype())));
            }
            let values = view
                .data()
                .chunks_exact(8)
                .map(|b| f64::from_le_bytes(b.try_into().expect("chunks of 8 bytes")))
                .collect();
            Ok((name, values))
        })
        .collect()
}

/// The `kind` an inertial correction's `config.json` names
/// (`weft_surrogate::inertial_correction::KIND`).
pub const INERTIAL_CORRECTION: &str = "inertial-correction";

/// The `kind` the nonlinear inertial correction's `config.json` names (weft-nn's
/// `inertial_correction_mlp`, trained with candle): told apart here so that this crate's
/// loader, which has no network, refuses it by name.
pub const INERTIAL_CORRECTION_MLP: &str = "inertial-correction-mlp";

/// The kind of model a stored `config.json` belongs to, by the fields only that kind's
/// configuration has: `drape` (a stamp of `config`, `layer` and the starting weights), `embed`
/// (`autoencoder`), `altconv` (`variant` and `steps`), `nnwarp` (`material`) or
/// `inertial-correction` or `inertial-correction-mlp` (their `kind`).
pub fn stored_model_kind(config: &serde_json::Value) -> Option<&'static str> {
    let kind = config.get("kind").and_then(|k| k.as_str());
    if let Some(k) = [INERTIAL_CORRECTION, INERTIAL_CORRECTION_MLP]
        .into_iter()
        .find(|k| kind == Some(*k))
    {
        Some(k)
    } else if config.get("config").is_some() && config.get("layer").is_some() {
        Some("drape")
    } else if config.get("autoencoder").is_some() {
        Some("embed")
    } else if config.get("variant").is_some() && config.get("steps").is_some() {
        Some("altconv")
    } else if config.get("material").is_some() {
        Some("nnwarp")
    } else {
        None
    }
}

/// Checks that the model directory `dir` holds an `expected` model (see
/// [`stored_model_kind`]): a directory of another kind is an error naming both kinds,
/// rather than whatever field of the other configuration fails to parse first. A
/// directory whose kind is not recognised passes (its own loader reports what is wrong).
pub fn check_model_kind(dir: &Path, expected: &'static str) -> Result<()> {
    let path = dir.join("config.json");
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(());
    };
    let kind = serde_json::from_str::<serde_json::Value>(&text)
        .ok()
        .as_ref()
        .and_then(stored_model_kind);
    match kind {
        Some(k) if k != expected => Err(Error::Checkpoint {
            path: path.display().to_string(),
            reason: format!("{} holds a `{k}` model, not a `{expected}` one", dir.display()),
        }),
        _ => Ok(()),
    }
}
