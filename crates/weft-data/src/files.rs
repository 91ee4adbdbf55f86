//! Writing result files: safetensors arrays, JSON and text, each written to a temporary
//! name and renamed into place so a crash never leaves a half-written file behind; SHA-256
//! checksums; and the one progress-bar style.

use std::collections::HashMap;
use std::path::Path;

use indicatif::{ProgressBar, ProgressStyle};
use safetensors::tensor::Dtype;
use sha2::{Digest, Sha256};

use crate::error::{Error, Result, ensure};

/// A named array with its shape, as little-endian bytes.
#[derive(Debug, Clone)]
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
    pub fn i64(name: &str, data: &[i64]) -> Self {
        Self {
            name: name.into(),
            shape: vec![data.len()],
            bytes: data.iter().flat_map(|v| v.to_le_bytes()).collect(),
            dtype: Dtype::I64,
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

/// Serialises arrays to safetensors bytes, deterministically: the safetensors crate
/// writes its metadata map in hash order, which differs between runs, so the header is
/// built here with sorted metadata keys and the tensors in the order given (the format:
/// an 8-byte little-endian header length, a JSON header padded with spaces to a multiple
/// of 8 bytes, then the tensors' bytes back to back).
pub fn safetensors_bytes(arrays: &[Array], metadata: HashMap<String, String>) -> Result<Vec<u8>> {
    let mut header = serde_json::Map::new();
    let sorted: std::collections::BTreeMap<_, _> = metadata.into_iter().collect();
    header.insert("__metadata__".into(), serde_json::to_value(sorted)?);
    let mut offset = 0usize;
    for a in arrays {
        let dtype = match a.dtype {
            Dtype::F64 => "F64",
            Dtype::U8 => "U8",
            Dtype::I64 => "I64",
            other => {
                return Err(Error::Invalid(format!(
                    "array {}: dtype {other:?} is not written by weft",
                    a.name
                )));
            }
        };
        let width = if a.dtype == Dtype::U8 { 1 } else { 8 };
        ensure!(
            a.shape.iter().product::<usize>() * width == a.bytes.len(),
            "array {}: shape {:?} does not match its {} bytes",
            a.name,
            a.shape,
            a.bytes.len()
        );
        header.insert(
            a.name.clone(),
            serde_json::json!({"dtype": dtype, "shape": a.shape, "data_offsets": [offset, offset + a.bytes.len()]}),
        );
        offset += a.bytes.len();
    }
    let mut json = serde_json::to_string(&serde_json::Value::Object(header))?.into_bytes();
    while json.len() % 8 != 0 {
        json.push(b' ');
    }
    let mut out = Vec::with_capacity(8 + json.len() + offset);
    out.extend_from_slice(&(json.len() as u64).to_le_bytes());
    out.extend_from_slice(&json);
    for a in arrays {
        out.extend_from_slice(&a.bytes);
    }
    Ok(out)
}

pub fn write_safetensors(path: &Path, arrays: &[Array], metadata: HashMap<String, String>) -> Result<()> {
    write_bytes(path, &safetensors_bytes(arrays, metadata)?)
}

/// Writes `bytes` to `path.tmp`, then renames it into place.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = std::path::PathBuf::from(tmp);
    std::fs::write(&tmp, bytes).map_err(|e| Error::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

pub fn write_text(path: &Path, text: &str) -> Result<()> {
    write_bytes(path, text.as_bytes())
}

pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let mut text = serde_json::to_string_pretty(value)?;
    text.push('\n');
    write_text(path, &text)
}

/// Lower-case hex SHA-256 of some bytes.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

/// SHA-256 of a file's contents.
pub fn sha256_file(path: &Path) -> Result<String> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    Ok(sha256_hex(&bytes))
}

/// A progress bar with rate and ETA (hidden with `quiet`).
pub fn progress_bar(quiet: bool, len: u64, prefix: &str, unit: &str) -> Result<ProgressBar> {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(len)
    };
    bar.set_style(
        ProgressStyle::with_template(&format!(
            "{{prefix}} [{{bar:40}}] {{pos}}/{{len}} {unit}, {{per_sec}}, ETA {{eta}} {{msg}}"
        ))?
        .progress_chars("=> "),
    );
    bar.set_prefix(prefix.to_string());
    Ok(bar)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn safetensors_bytes_are_deterministic_and_read_back_by_the_safetensors_crate() {
        let arrays = || {
            vec![
                Array::f64("positions", vec![2, 1, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, -6.5]),
                Array::u8("labels", &[3, 7]),
            ]
        };
        let meta = || -> HashMap<String, String> { (0..20).map(|i| (format!("key{i}"), format!("v{i}"))).collect() };
        let a = safetensors_bytes(&arrays(), meta()).unwrap();
        let b = safetensors_bytes(&arrays(), meta()).unwrap();
        assert_eq!(a, b);
        let st = safetensors::SafeTensors::deserialize(&a).unwrap();
        let p = st.tensor("positions").unwrap();
        assert_eq!(p.shape(), [2, 1, 3]);
        let values: Vec<f64> = p
            .data()
            .chunks(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        assert_eq!(values, [1.0, 2.0, 3.0, 4.0, 5.0, -6.5]);
        assert_eq!(st.tensor("labels").unwrap().data(), [3, 7]);
        let (_, header) = safetensors::SafeTensors::read_metadata(&a).unwrap();
        assert_eq!(header.metadata().as_ref().unwrap()["key13"], "v13");
    }
}
