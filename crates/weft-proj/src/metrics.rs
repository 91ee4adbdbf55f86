//! Edge-strain diagnostics reported before and after a projection: the largest strain
//! and the stretching / compression split of the edge spring energy (project metric (g):
//! `E_edge = Σ ½ k (l − l̄)²` over stretched (`l > l̄`) and compressed (`l < l̄`) edges).

use crate::error::Result;
use crate::rest::{RestShape, edge_vector};

/// Edge strain statistics of one configuration.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct StrainSummary {
    /// `max_e (l_e / l̄_e − 1)`: the largest relative elongation.
    pub max_strain: f64,
    /// `min_e (l_e / l̄_e − 1)`: the largest relative compression (negative).
    pub min_strain: f64,
    /// `Σ_{l > l̄} ½ k (l − l̄)²` (J) with the given edge stiffness `k`.
    pub stretching_energy: f64,
    /// `Σ_{l < l̄} ½ k (l − l̄)²` (J).
    pub compression_energy: f64,
}

/// Strain summary of flat positions `x` against the rest shape, edge stiffness `k` (N/m).
pub fn strain_summary(rest: &RestShape, x: &[f64], k: f64) -> Result<StrainSummary> {
    rest.check_positions("positions", x)?;
    let mut s = StrainSummary {
        max_strain: f64::NEG_INFINITY,
        min_strain: f64::INFINITY,
        stretching_energy: 0.0,
        compression_energy: 0.0,
    };
    for (&[a, b], &l0) in rest.edges().iter().zip(rest.rest_lengths()) {
        let l = edge_vector(x, a, b).norm();
        let strain = l / l0 - 1.0;
        s.max_strain = s.max_strain.max(strain);
        s.min_strain = s.min_strain.min(strain);
        let e = 0.5 * k * (l - l0).powi(2);
        if l > l0 {
            s.stretching_energy += e;
        } else {
            s.compression_energy += e;
        }
    }
    Ok(s)
}
