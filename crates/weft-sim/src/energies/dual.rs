//! First-order forward-mode differentiation, used to get exact Hessians by
//! differentiating a hand-written gradient (the dihedral angle's, Tan et al. Fig. 1d)
//! instead of hand-deriving its long second derivative.
//!
//! [`Real`] abstracts the few operations the gradient formula uses, so the same code
//! evaluates the gradient in `f64` and its Jacobian (the Hessian) in [`Dual<N>`].

use std::ops::{Add, Div, Mul, Neg, Sub};

use nalgebra::SVector;

/// The arithmetic a formula needs to run on both `f64` and [`Dual`].
pub trait Real:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> + Neg<Output = Self>
{
    fn cst(v: f64) -> Self;
    fn sqrt(self) -> Self;
}

impl Real for f64 {
    fn cst(v: f64) -> Self {
        v
    }
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
}

/// A value with its gradient with respect to `N` inputs.
#[derive(Debug, Clone, Copy)]
pub struct Dual<const N: usize> {
    pub v: f64,
    pub d: SVector<f64, N>,
}

impl<const N: usize> Dual<N> {
    /// Independent variable `i` with value `v`.
    pub fn variable(v: f64, i: usize) -> Self {
        let mut d = SVector::zeros();
        d[i] = 1.0;
        Self { v, d }
    }
}

impl<const N: usize> Real for Dual<N> {
    fn cst(v: f64) -> Self {
        Self { v, d: SVector::zeros() }
    }
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        Self {
            v: s,
            d: self.d * (0.5 / s),
        }
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            v: self.v + o.v,
            d: self.d + o.d,
        }
    }
}
impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self {
            v: self.v - o.v,
            d: self.d - o.d,
        }
    }
}
impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    fn mul(self, o: Self) -> Self {
        Self {
            v: self.v * o.v,
            d: self.d * o.v + o.d * self.v,
        }
    }
}
impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    fn div(self, o: Self) -> Self {
        let inv = 1.0 / o.v;
        Self {
            v: self.v * inv,
            d: (self.d - o.d * (self.v * inv)) * inv,
        }
    }
}
impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    fn neg(self) -> Self {
        Self { v: -self.v, d: -self.d }
    }
}

/// A 3-vector over any [`Real`].
#[derive(Debug, Clone, Copy)]
pub struct V3<T>(pub [T; 3]);

impl<T: Real> V3<T> {
    pub fn sub(&self, o: &Self) -> Self {
        Self([0, 1, 2].map(|c| self.0[c] - o.0[c]))
    }
    pub fn dot(&self, o: &Self) -> T {
        self.0[0] * o.0[0] + self.0[1] * o.0[1] + self.0[2] * o.0[2]
    }
    pub fn cross(&self, o: &Self) -> Self {
        let (a, b) = (&self.0, &o.0);
        Self([
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ])
    }
    pub fn scale(&self, s: T) -> Self {
        Self(self.0.map(|c| c * s))
    }
    pub fn add(&self, o: &Self) -> Self {
        Self([0, 1, 2].map(|c| self.0[c] + o.0[c]))
    }
}
