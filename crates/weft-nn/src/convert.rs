//! The one place where f32 network tensors meet the f64 physics.
//!
//! Networks run in f32; simulation and geometry run in f64 (metres, newtons, joules). Every
//! crossing goes through these functions, which check finiteness on the way: a NaN from a
//! diverging network is a typed error here, never an input to a solver, and a NaN from a
//! solver never enters a gradient.

use candle_core::{DType, Device, Tensor};
use nalgebra::Vector3;

use crate::error::{Error, Result};

/// The index of the first non-finite entry of `values`, if any.
fn first_non_finite<T: Copy + Into<f64>>(values: &[T]) -> Option<usize> {
    values.iter().position(|v| !(*v).into().is_finite())
}

/// An f32 tensor of `shape` from f64 values (rounded to nearest).
pub fn f64_to_tensor(what: &'static str, values: &[f64], shape: &[usize], device: &Device) -> Result<Tensor> {
    if let Some(index) = first_non_finite(values) {
        return Err(Error::NonFinite { what, index });
    }
    let expected: usize = shape.iter().product();
    if values.len() != expected {
        return Err(Error::Shape {
            what,
            expected: format!("{shape:?} ({expected} values)"),
            got: format!("{} values", values.len()),
        });
    }
    let v: Vec<f32> = values.iter().map(|&x| x as f32).collect();
    Ok(Tensor::from_vec(v, shape, device)?)
}

/// The entries of any float tensor as f64, in row-major order.
pub fn tensor_to_f64(what: &'static str, t: &Tensor) -> Result<Vec<f64>> {
    let v: Vec<f64> = t.to_dtype(DType::F64)?.flatten_all()?.to_vec1()?;
    if let Some(index) = first_non_finite(&v) {
        return Err(Error::NonFinite { what, index });
    }
    Ok(v)
}

/// f32 slice → f64 vertex positions (`[x0, y0, z0, x1, …]`), checked.
pub fn f32_to_points(what: &'static str, values: &[f32]) -> Result<Vec<Vector3<f64>>> {
    if let Some(index) = first_non_finite(values) {
        return Err(Error::NonFinite { what, index });
    }
    if !values.len().is_multiple_of(3) {
        return Err(Error::Shape {
            what,
            expected: "a multiple of 3 values".into(),
            got: format!("{} values", values.len()),
        });
    }
    Ok(values
        .chunks_exact(3)
        .map(|c| Vector3::new(c[0] as f64, c[1] as f64, c[2] as f64))
        .collect())
}

/// f64 values → f32, checked (for results of the physics going back into a graph).
pub fn f64_to_f32(what: &'static str, values: &[f64]) -> Result<Vec<f32>> {
    if let Some(index) = first_non_finite(values) {
        return Err(Error::NonFinite { what, index });
    }
    Ok(values.iter().map(|&x| x as f32).collect())
}

/// f32 values → f64, checked.
pub fn f32_to_f64(what: &'static str, values: &[f32]) -> Result<Vec<f64>> {
    if let Some(index) = first_non_finite(values) {
        return Err(Error::NonFinite { what, index });
    }
    Ok(values.iter().map(|&x| x as f64).collect())
}

/// `f` on the values of a contiguous f32 CPU tensor, borrowed from its storage (no copy);
/// a tensor of another layout is copied first.
pub(crate) fn with_f32_values<R>(t: &Tensor, f: impl FnOnce(&[f32]) -> R) -> candle_core::Result<R> {
    {
        let (storage, layout) = t.storage_and_layout();
        if let (candle_core::Storage::Cpu(s), Some((a, b))) = (&*storage, layout.contiguous_offsets()) {
            return Ok(f(&s.as_slice::<f32>()?[a..b]));
        }
    }
    let copy: Vec<f32> = t.flatten_all()?.to_vec1()?;
    Ok(f(&copy))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_non_finite_values_are_rejected() {
        let d = Device::Cpu;
        let t = f64_to_tensor("x", &[1.0, -2.5, 3.25], &[3], &d).unwrap();
        assert_eq!(tensor_to_f64("x", &t).unwrap(), vec![1.0, -2.5, 3.25]);
        assert!(matches!(
            f64_to_tensor("x", &[1.0, f64::NAN], &[2], &d),
            Err(Error::NonFinite { index: 1, .. })
        ));
        assert!(matches!(f64_to_tensor("x", &[1.0], &[2], &d), Err(Error::Shape { .. })));
        let bad = Tensor::new(&[0.0f32, f32::INFINITY], &d).unwrap();
        assert!(matches!(
            tensor_to_f64("y", &bad),
            Err(Error::NonFinite { index: 1, .. })
        ));
        assert!(f32_to_points("p", &[0.0, 1.0]).is_err());
        assert_eq!(
            f32_to_points("p", &[0.0, 1.0, 2.0]).unwrap()[0],
            Vector3::new(0.0, 1.0, 2.0)
        );
    }
}
