//! Writing result files: safetensors arrays and JSON, each written to a temporary name
//! and renamed into place so a crash never leaves a half-written file behind.

use std::collections::HashMap;
use std::path::Path;

use anyhow::Context;
use safetensors::tensor::{Dtype, TensorView};

/// A named f64 array with its shape.
pub struct Array {
    pub name: String,
    pub shape: Vec<usize>,
    pub bytes: Vec<u8>,
    pub dtype: Dtype,
}

impl Array {
    pub fn f64(name: &str, shape: Vec<usize>, data: &[f64]) -> Self {
        assert_eq!(
            shape.iter().product::<usize>(),
            data.len(),
            "array {name}: shape does not match data"
        );
        Self {
            name: name.into(),
            shape,
            bytes: data.iter().flat_map(|v| v.to_le_bytes()).collect(),
            dtype: Dtype::F64,
        }
    }
    pub fn u8(name: &str, data: &[u8]) -> Self {
        Self {
            name: name.into(),
            shape: vec![data.len()],
            bytes: data.to_vec(),
            dtype: Dtype::U8,
        }
    }
}

pub fn write_safetensors(path: &Path, arrays: &[Array], metadata: HashMap<String, String>) -> anyhow::Result<()> {
    let views = arrays
        .iter()
        .map(|a| Ok((a.name.clone(), TensorView::new(a.dtype, a.shape.clone(), &a.bytes)?)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let tmp = path.with_extension("safetensors.tmp");
    safetensors::tensor::serialize_to_file(views, Some(metadata), &tmp)
        .with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming into {}", path.display()))
}

pub fn write_text(path: &Path, text: &str) -> anyhow::Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, text).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming into {}", path.display()))
}

pub fn write_json(path: &Path, value: &impl serde::Serialize) -> anyhow::Result<()> {
    write_text(path, &serde_json::to_string_pretty(value)?)
}
