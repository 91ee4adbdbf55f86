//! Loose array files outside a dataset: `.npy` arrays of floats (what `cargo xtask acap`
//! writes and numpy users hand it) and the `positions` frames of a `simulate` output's
//! `frames.safetensors`.
//!
//! Every reader checks what it is given before trusting it: the dtype, the shape against
//! what the caller expects, and the element count a header claims against the bytes
//! present, before anything is allocated for it. Arbitrary bytes give an error, never a
//! panic.
//!
//! What is not here: the dataset readers (their files carry a manifest and checksums;
//! they are [`crate::read`]'s), and the safetensors writer ([`crate::files`]).

use std::path::Path;

use nalgebra::Vector3;
use npyz::WriterBuilder;

use crate::error::{Context, Error, Result, ensure};

/// The shape and the values (row-major, widened to f64) of an `.npy` array.
pub type NpyArray = (Vec<u64>, Vec<f64>);

/// The shape and values of `.npy` bytes holding float64, or float32 (as numpy users often
/// save features) widened to f64 exactly. The element count the header claims is checked
/// against the bytes present before anything is allocated for it.
pub fn parse_npy(bytes: &[u8]) -> Result<NpyArray> {
    let npy = npyz::NpyFile::new(bytes).map_err(|e| Error::Invalid(format!("not an .npy file: {e}")))?;
    let shape = npy.shape().to_vec();
    let dtype = npy.dtype();
    let width = match &dtype {
        npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Float && matches!(t.size_field(), 4 | 8) => {
            t.size_field()
        }
        other => {
            return Err(Error::Invalid(format!(
                "expected float64 or float32 values, found dtype {}",
                other.descr()
            )));
        }
    };
    let count = shape
        .iter()
        .try_fold(1u64, |a, &d| a.checked_mul(d))
        .context("the header's shape overflows")?;
    ensure!(
        count.checked_mul(width).is_some_and(|b| b <= bytes.len() as u64),
        "the header claims {count} values ({shape:?}) of {width} bytes but the file has {} bytes",
        bytes.len()
    );
    let values = if width == 8 {
        npy.into_vec::<f64>()
            .map_err(|e| Error::Invalid(format!("reading float64 values: {e}")))?
    } else {
        npy.into_vec::<f32>()
            .map_err(|e| Error::Invalid(format!("reading float32 values: {e}")))?
            .into_iter()
            .map(f64::from)
            .collect()
    };
    Ok((shape, values))
}

/// [`parse_npy`] of the file at `path`.
pub fn read_npy(path: &Path) -> Result<NpyArray> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_npy(&bytes).with_context(|| format!("in {}", path.display()))
}

/// `.npy` bytes (format 1.0, little-endian float64) of `values` in the row-major `shape`.
pub fn npy_bytes(shape: &[u64], values: impl IntoIterator<Item = f64>) -> Result<Vec<u8>> {
    let npy_error = |e: std::io::Error| Error::Invalid(format!("writing .npy values of shape {shape:?}: {e}"));
    let mut out = Vec::new();
    let mut writer = npyz::WriteOptions::<f64>::new()
        .default_dtype()
        .shape(shape)
        .writer(&mut out)
        .begin_nd()
        .map_err(npy_error)?;
    writer.extend(values).map_err(npy_error)?;
    writer.finish().map_err(npy_error)?;
    Ok(out)
}

/// Writes [`npy_bytes`] to `path` (through a temporary name renamed into place).
pub fn write_npy(path: &Path, shape: &[u64], values: impl IntoIterator<Item = f64>) -> Result<()> {
    let bytes = npy_bytes(shape, values).with_context(|| format!("writing {}", path.display()))?;
    crate::files::write_bytes(path, &bytes)
}

/// The frames of safetensors bytes' `positions` tensor (f64, `[frames, nv, 3]`): what
/// `cargo xtask simulate` writes as `frames.safetensors`.
pub fn parse_safetensors_frames(bytes: &[u8], nv: usize) -> Result<Vec<Vec<Vector3<f64>>>> {
    ensure!(nv > 0, "the rest mesh has no vertex");
    let tensors = safetensors::SafeTensors::deserialize(bytes).context("not safetensors")?;
    let t = tensors.tensor("positions").context("no tensor `positions`")?;
    ensure!(
        t.dtype() == safetensors::Dtype::F64,
        "`positions` must be f64, is {:?}",
        t.dtype()
    );
    let shape = t.shape();
    ensure!(
        shape.len() == 3 && shape[1] == nv && shape[2] == 3,
        "`positions` has shape {shape:?}, expected [frames, {nv}, 3]"
    );
    let values: Vec<f64> = t
        .data()
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().expect("chunks of 8")))
        .collect();
    Ok(values
        .chunks_exact(3 * nv)
        .map(|f| f.chunks_exact(3).map(|c| Vector3::new(c[0], c[1], c[2])).collect())
        .collect())
}

/// [`parse_safetensors_frames`] of the file at `path`.
pub fn read_safetensors_frames(path: &Path, nv: usize) -> Result<Vec<Vec<Vector3<f64>>>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_safetensors_frames(&bytes, nv).with_context(|| format!("in {}", path.display()))
}

/// The string metadata entry `key` of the safetensors file at `path`, if it has one.
pub fn safetensors_metadata(path: &Path, key: &str) -> Result<Option<String>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let (_, header) =
        safetensors::SafeTensors::read_metadata(&bytes).with_context(|| format!("parsing {}", path.display()))?;
    Ok(header.metadata().as_ref().and_then(|m| m.get(key).cloned()))
}

/// The pins `cargo xtask acap encode` records beside a features file `F.npy`: their vertex
/// indices in `F.pins.json` (this), their positions per frame in `F.pins.npy`
/// (`[frames, pins, 3]`, f64), so that decoding can place them where the input had them.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PinRecord {
    /// Vertex indices of the pins, in the order of `F.pins.npy`'s second axis.
    pub pins: Vec<usize>,
    pub frames: usize,
}

/// `F.pins.<ext>` beside the features file `F.npy`.
pub fn pin_file(features: &Path, ext: &str) -> std::path::PathBuf {
    let stem = features
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    features.with_file_name(format!("{stem}.pins.{ext}"))
}

/// Writes ACAP features (`[frames, vertices, 9]`, f64, frame by frame) to `out`, and beside
/// it the pins' record and per-frame positions ([`PinRecord`]); with no pins, removes pin
/// files an earlier write left under the same name, which would otherwise be read as this
/// one's.
pub fn write_features(
    out: &Path,
    features: &[Vec<[f64; 9]>],
    pins: &[usize],
    pin_positions: impl IntoIterator<Item = f64>,
) -> Result<()> {
    let frames = features.len();
    let nv = features.first().map_or(0, Vec::len);
    ensure!(
        features.iter().all(|f| f.len() == nv),
        "every frame's features must cover the same vertices"
    );
    write_npy(
        out,
        &[frames as u64, nv as u64, 9],
        features.iter().flatten().flatten().copied(),
    )?;
    if pins.is_empty() {
        for ext in ["npy", "json"] {
            let stale = pin_file(out, ext);
            if stale.exists() {
                std::fs::remove_file(&stale).map_err(|e| Error::io(&stale, e))?;
            }
        }
        return Ok(());
    }
    write_npy(
        &pin_file(out, "npy"),
        &[frames as u64, pins.len() as u64, 3],
        pin_positions,
    )?;
    let record = PinRecord {
        pins: pins.to_vec(),
        frames,
    };
    crate::files::write_text(&pin_file(out, "json"), &serde_json::to_string_pretty(&record)?)
}

/// The ACAP features in `path` (`[frames, nv, 9]`, or `[nv, 9]` for one frame; f32 is
/// widened), per frame and vertex.
pub fn read_features(path: &Path, nv: usize) -> Result<Vec<Vec<[f64; 9]>>> {
    let (shape, values) = read_npy(path)?;
    let (frames, v) = match shape.as_slice() {
        [v, 9] => (1, *v),
        [f, v, 9] => (*f, *v),
        other => {
            return Err(Error::Invalid(format!(
                "features must have shape [frames, vertices, 9] or [vertices, 9], got {other:?}"
            )));
        }
    };
    ensure!(v as usize == nv, "features have {v} vertices, the rest mesh {nv}");
    let features: Vec<Vec<[f64; 9]>> = values
        .chunks_exact(9 * nv.max(1))
        .map(|frame| {
            frame
                .chunks_exact(9)
                .map(|c| c.try_into().expect("chunks of 9"))
                .collect()
        })
        .collect();
    ensure!(
        features.len() == frames as usize,
        "features hold {} frames, their header {frames}",
        features.len()
    );
    Ok(features)
}

/// The [`PinRecord`] beside the features file `features`, if there is one.
pub fn read_pin_record(features: &Path) -> Result<Option<PinRecord>> {
    match std::fs::read_to_string(pin_file(features, "json")) {
        Ok(text) => Ok(Some(
            serde_json::from_str(&text).context("parsing the pin sidecar JSON")?,
        )),
        Err(_) => Ok(None),
    }
}

/// The per-frame positions of `pins` pins recorded beside the features file `features`.
pub fn read_pin_positions(features: &Path, frames: usize, pins: usize) -> Result<Vec<Vec<Vector3<f64>>>> {
    let (shape, values) = read_npy(&pin_file(features, "npy"))?;
    ensure!(
        shape == [frames as u64, pins as u64, 3],
        "pin positions have shape {shape:?}, expected [{frames}, {pins}, 3]"
    );
    Ok(values
        .chunks_exact(3 * pins.max(1))
        .map(|f| f.chunks_exact(3).map(|c| Vector3::new(c[0], c[1], c[2])).collect())
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::files::{Array, safetensors_bytes};

    fn npy_of<T: npyz::AutoSerialize + Copy>(shape: &[u64], values: &[T]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut w = npyz::WriteOptions::<T>::new()
            .default_dtype()
            .shape(shape)
            .writer(&mut out)
            .begin_nd()
            .unwrap();
        w.extend(values.iter().copied()).unwrap();
        w.finish().unwrap();
        out
    }

    #[test]
    fn npy_of_float32_is_widened_and_other_dtypes_are_named() {
        let bytes = npy_of(&[2, 2], &[0.1f32, -2.5, 3.0, 1e-7]);
        let (shape, values) = parse_npy(&bytes).unwrap();
        assert_eq!(shape, vec![2, 2]);
        assert_eq!(values, vec![f64::from(0.1f32), -2.5, 3.0, f64::from(1e-7f32)]);
        let err = parse_npy(&npy_of(&[3], &[1i32, 2, 3])).unwrap_err();
        assert!(matches!(err, Error::Invalid(_)), "{err:?}");
        assert!(
            err.to_string()
                .contains("expected float64 or float32 values, found dtype '<i4'"),
            "{err}"
        );
    }

    #[test]
    fn npy_round_trips_through_bytes_and_files_and_a_lying_header_is_a_typed_error() {
        let values: Vec<f64> = (0..18).map(|i| i as f64 * 0.5 - 3.0).collect();
        let bytes = npy_bytes(&[2, 3, 3], values.iter().copied()).unwrap();
        assert_eq!(bytes, npy_of(&[2, 3, 3], &values), "the writer is plain float64 .npy");
        assert_eq!(parse_npy(&bytes).unwrap(), (vec![2, 3, 3], values.clone()));
        let path = std::env::temp_dir().join(format!("weft-arrays-{}.npy", std::process::id()));
        write_npy(&path, &[6, 3], values.iter().copied()).unwrap();
        assert_eq!(read_npy(&path).unwrap(), (vec![6, 3], values));
        std::fs::remove_file(&path).unwrap();
        assert!(matches!(read_npy(&path), Err(Error::Io { .. })));
        // Regression: the header's shape was trusted, so a file claiming 10^15 values
        // allocated for them before reading.
        let (old, lying): (&[u8], &[u8]) = (b"(2, 3, 3, )", b"(999999999999999, 3, 3, )");
        let at = bytes.windows(old.len()).position(|w| w == old).unwrap();
        let mut lied = bytes.clone();
        lied.splice(at..at + old.len(), lying.iter().copied());
        // Keep the header's length: take the extra characters out of its space padding.
        let newline = lied.iter().position(|&b| b == b'\n').unwrap();
        lied.drain(newline - (lying.len() - old.len())..newline);
        assert_eq!(lied.len(), bytes.len());
        let err = parse_npy(&lied).unwrap_err();
        assert!(
            matches!(err, Error::Invalid(_)) && err.to_string().contains("claims"),
            "{err}"
        );
    }

    #[test]
    fn features_and_their_pins_round_trip_and_stale_pins_are_removed() {
        let dir = std::env::temp_dir().join(format!("weft-arrays-features-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("f.npy");
        let features: Vec<Vec<[f64; 9]>> = (0..3)
            .map(|k| {
                (0..2)
                    .map(|v| std::array::from_fn(|i| (9 * (2 * k + v) + i) as f64))
                    .collect()
            })
            .collect();
        let positions: Vec<f64> = (0..3 * 3).map(|i| i as f64 * 0.1).collect();
        write_features(&out, &features, &[4], positions.iter().copied()).unwrap();
        assert_eq!(read_features(&out, 2).unwrap(), features);
        assert!(
            read_features(&out, 3)
                .unwrap_err()
                .to_string()
                .contains("the rest mesh 3")
        );
        let record = read_pin_record(&out).unwrap().unwrap();
        assert_eq!(
            record,
            PinRecord {
                pins: vec![4],
                frames: 3
            }
        );
        let read = read_pin_positions(&out, 3, 1).unwrap();
        assert_eq!(read[2][0], Vector3::new(positions[6], positions[7], positions[8]));
        write_features(&out, &features[..1], &[], []).unwrap();
        assert_eq!(read_pin_record(&out).unwrap(), None);
        assert!(!pin_file(&out, "npy").exists());
        assert_eq!(read_features(&out, 2).unwrap(), features[..1]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn safetensors_frames_round_trip_and_their_metadata_is_read() {
        let values: Vec<f64> = (0..12).map(|i| f64::from(i) * 0.25).collect();
        let metadata = [("grasp_vertices".to_string(), "[0,1]".to_string())].into();
        let bytes = safetensors_bytes(&[Array::f64("positions", vec![2, 2, 3], &values)], metadata).unwrap();
        let frames = parse_safetensors_frames(&bytes, 2).unwrap();
        let flat: Vec<f64> = frames.iter().flatten().flat_map(|p| [p.x, p.y, p.z]).collect();
        assert_eq!((frames.len(), flat), (2, values));
        let err = parse_safetensors_frames(&bytes, 3).unwrap_err();
        assert!(err.to_string().contains("expected [frames, 3, 3]"), "{err}");
        let path = std::env::temp_dir().join(format!("weft-arrays-{}.safetensors", std::process::id()));
        crate::files::write_bytes(&path, &bytes).unwrap();
        assert_eq!(read_safetensors_frames(&path, 2).unwrap(), frames);
        assert_eq!(
            safetensors_metadata(&path, "grasp_vertices").unwrap().as_deref(),
            Some("[0,1]")
        );
        assert_eq!(safetensors_metadata(&path, "other").unwrap(), None);
        std::fs::remove_file(&path).unwrap();
    }

    proptest::proptest! {
        /// Arbitrary, corrupted and truncated bytes give errors, never a panic.
        #[test]
        fn npy_and_safetensors_readers_never_panic(
            random in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..300),
            flips in proptest::collection::vec(
                (proptest::prelude::any::<proptest::sample::Index>(), proptest::prelude::any::<u8>()),
                1..8,
            ),
            cut in proptest::prelude::any::<proptest::sample::Index>(),
        ) {
            let _ = parse_npy(&random);
            let _ = parse_safetensors_frames(&random, 2);
            let mut npy = npy_bytes(&[2, 3], [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
            let arrays = [Array::f64("positions", vec![1, 2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0])];
            let mut st = safetensors_bytes(&arrays, Default::default()).unwrap();
            for (i, b) in &flips {
                let k = i.index(npy.len());
                npy[k] ^= b;
                let k = i.index(st.len());
                st[k] ^= b;
            }
            let _ = parse_npy(&npy);
            let _ = parse_safetensors_frames(&st, 2);
            let _ = parse_npy(&npy[..cut.index(npy.len())]);
            let _ = parse_safetensors_frames(&st[..cut.index(st.len())], 2);
        }
    }
}
