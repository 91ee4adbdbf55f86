//! Body-force fields of NNWarp §3.2 as [`ConstantForce`] constructors: a directional
//! field (a uniform acceleration, of which gravity is one) and a circular field whose
//! direction follows the tangents of circles concentric about an axis.
//!
//! Both are dead loads: evaluated once at the rest positions and held constant while
//! the body deforms, as in NNWarp's training-data generation.

use nalgebra::Vector3;

use super::ConstantForce;
use crate::energy::vertex;
use crate::error::{Error, Result, check_nonnegative};

impl ConstantForce {
    /// A directional field: every vertex feels `m_i a ê` (N), `ê = direction/‖direction‖`,
    /// `acceleration` `a` in m/s².
    pub fn directional(masses: &[f64], direction: [f64; 3], acceleration: f64) -> Result<Self> {
        let e = unit("force direction", Vector3::from(direction))?;
        if !acceleration.is_finite() {
            return Err(Error::InvalidParameter {
                name: "field acceleration",
                value: acceleration,
                reason: "must be finite",
            });
        }
        let g = e * acceleration;
        Self::new(
            "directional force field",
            masses.iter().flat_map(|m| [m * g.x, m * g.y, m * g.z]).collect(),
        )
    }

    /// A circular field about the axis through `center` along `axis`: vertex `i` at rest
    /// position `p_i` feels `m_i a (â × r̂_i)` (N), with `r_i` the component of
    /// `p_i − center` orthogonal to the axis — the tangent of the circle through `p_i`,
    /// counter-clockwise about `â`. Vertices on the axis feel nothing. `rest` is flat
    /// (3 per vertex, m); `acceleration` `a` in m/s² (non-negative; flip `axis` to reverse).
    pub fn circular(masses: &[f64], rest: &[f64], center: [f64; 3], axis: [f64; 3], acceleration: f64) -> Result<Self> {
        if rest.len() != 3 * masses.len() {
            return Err(Error::LengthMismatch {
                what: "rest positions",
                expected: 3 * masses.len(),
                got: rest.len(),
            });
        }
        check_nonnegative("field acceleration", acceleration)?;
        let a = unit("circular field axis", Vector3::from(axis))?;
        let c = Vector3::from(center);
        // Distances below this fraction of the body's extent count as "on the axis".
        let extent = (0..masses.len())
            .map(|i| (vertex(rest, i) - c).norm())
            .fold(0.0f64, f64::max);
        let tiny = 1e-12 * extent.max(f64::MIN_POSITIVE);
        let mut forces = Vec::with_capacity(rest.len());
        for (i, m) in masses.iter().enumerate() {
            let d = vertex(rest, i) - c;
            let r = d - a * a.dot(&d);
            let t = if r.norm() > tiny {
                a.cross(&r) / r.norm()
            } else {
                Vector3::zeros()
            };
            forces.extend((m * acceleration * t).iter());
        }
        Self::new("circular force field", forces)
    }
}

/// NNWarp §5's sampling of force directions on a quarter hemisphere:
/// `ê = [sin β cos α, cos β, sin β sin α]` for `α, β ∈ [0, π/2]` (radians).
pub fn hemisphere_direction(alpha: f64, beta: f64) -> [f64; 3] {
    [beta.sin() * alpha.cos(), beta.cos(), beta.sin() * alpha.sin()]
}

fn unit(name: &'static str, v: Vector3<f64>) -> Result<Vector3<f64>> {
    let n = v.norm();
    if n.is_finite() && n > 0.0 {
        Ok(v / n)
    } else {
        Err(Error::InvalidParameter {
            name,
            value: n,
            reason: "must be a non-zero finite vector",
        })
    }
}
