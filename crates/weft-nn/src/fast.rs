//! f32 activations for the runtimes that evaluate trained weights outside candle
//! (NNWarp's correction, Alt-ConvLSTM's roll-out): branch-free, so that a pass over a
//! buffer vectorises, and compiled for the CPU's widest vectors through `pulp`'s run-time
//! dispatch (the workspace targets baseline x86-64).

/// `tanh` for the runtime's f32 activations, branch-free so that a pass over a
/// buffer vectorises: the input clamped to ±7.905 (where f32 `tanh` is 1 to within rounding)
/// and a [13/6] odd rational approximant there, the one Eigen uses for f32
/// (`generic_fast_tanh_float`). Within 4e-7 of the exact value (tested), the network's own
/// f32 precision. Activations were most of the correction's time (docs/BENCHMARKS.md).
#[inline(always)]
pub fn tanh_f32(x: f32) -> f32 {
    const CLAMP: f32 = 7.905_311;
    const ALPHA: [f32; 7] = [
        4.893_524_6e-3,
        6.372_619e-4,
        1.485_722_4e-5,
        5.122_297e-8,
        -8.604_672e-11,
        2.000_188e-13,
        -2.760_768_5e-16,
    ];
    const BETA: [f32; 4] = [4.893_525e-3, 2.268_434_6e-3, 1.185_347_1e-4, 1.198_258_4e-6];
    let x = x.clamp(-CLAMP, CLAMP);
    let x2 = x * x;
    // Fused multiply-adds where the dispatched instruction set has them (everywhere
    // `pulp` picks its x86-64-v3 path).
    let p = ALPHA.iter().rev().fold(0.0f32, |acc, &a| acc.mul_add(x2, a));
    let q = BETA.iter().rev().fold(0.0f32, |acc, &b| acc.mul_add(x2, b));
    x * p / q
}

/// The logistic function through `σ(x) = (1 + tanh(x/2)) / 2`, within 2e-7 of the exact
/// value.
#[inline(always)]
pub fn sigmoid_f32(x: f32) -> f32 {
    0.5 + 0.5 * tanh_f32(0.5 * x)
}

/// [`tanh_f32`] over a buffer, compiled for the CPU's widest vectors (`pulp` dispatches
/// at run time; the workspace targets baseline x86-64).
struct TanhInPlace<'a>(&'a mut [f32]);

impl pulp::WithSimd for TanhInPlace<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        for v in self.0.iter_mut() {
            *v = tanh_f32(*v);
        }
    }
}

/// [`tanh_f32`] of every entry of `v`, in place.
pub fn tanh_in_place(v: &mut [f32]) {
    pulp::Arch::new().dispatch(TanhInPlace(v));
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_fast_tanh_is_tanh() {
        // Across and beyond the clamp: within 4e-7 of tanh, odd, saturating, monotone.
        let mut last = -1.0f32;
        for k in -20000..=20000 {
            let x = k as f32 / 2000.0;
            let t = super::tanh_f32(x);
            assert!((t as f64 - (x as f64).tanh()).abs() <= 4e-7, "{x}: {t}");
            assert_eq!(super::tanh_f32(-x), -t);
            // Monotone to within the approximation error.
            assert!(t >= last - 8e-7, "not monotone at {x}");
            last = t;
        }
        assert_eq!(super::tanh_f32(0.0), 0.0);
        assert!((super::tanh_f32(1e30) - 1.0).abs() < 4e-7);
        assert!(super::tanh_f32(f32::NAN).is_nan());
    }

    #[test]
    fn the_fast_sigmoid_is_the_logistic_function() {
        for k in -4000..=4000 {
            let x = k as f32 / 200.0;
            let exact = 1.0 / (1.0 + (-(x as f64)).exp());
            assert!((super::sigmoid_f32(x) as f64 - exact).abs() <= 2.5e-7, "{x}");
        }
        let mut v = vec![-3.0f32, 0.0, 0.5, 9.0];
        super::tanh_in_place(&mut v);
        for (t, x) in v.iter().zip([-3.0f32, 0.0, 0.5, 9.0]) {
            assert_eq!(*t, super::tanh_f32(x));
        }
    }
}
