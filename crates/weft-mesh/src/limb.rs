//! A tet-meshed soft-tissue limb around two rigid bones (design §6: the analogue of the
//! Dynamic FAUST bodies, which cannot be downloaded here).
//!
//! The body is a tapered cylinder of human-arm size along +X, from the shoulder (`x = 0`)
//! to the wrist (`x = length`), with an elbow joint at `joint · length`. It is a
//! structured grid of hexahedral cells (Kuhn split into 6 tets, as the beams) whose
//! square cross-section is mapped onto a disk by the radial map
//! `p ↦ p · ‖p‖_∞ / ‖p‖₂` (concentric squares onto concentric circles), then scaled by the
//! local radius. Nodes within `bone_radius` of the axis are *bone* nodes of the upper arm
//! (bone 0) or forearm (bone 1) — except in a gap around the elbow, where only tissue
//! connects the two — and every node of the shoulder face is attached to bone 0.
//!
//! Units: metres.

use nalgebra::Vector3;

use crate::error::{Error, Result};
use crate::generators::{BeamParams, beam};
use crate::tetmesh::TetMesh;

/// Shape and resolution of a [`Limb`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LimbParams {
    /// Shoulder-to-wrist length (m).
    pub length: f64,
    /// Radius at the shoulder and at the wrist (m); linear in between.
    pub root_radius: f64,
    pub tip_radius: f64,
    /// Cells across the (square, then disk-mapped) cross-section; even, so the axis is
    /// a line of nodes.
    pub cells_across: usize,
    /// Cells along the length.
    pub cells_along: usize,
    /// Elbow position as a fraction of the length.
    pub joint: f64,
    /// Bone radius as a fraction of the local body radius.
    pub bone_radius: f64,
    /// Length of the bone-free gap centred on the elbow (m).
    pub joint_gap: f64,
}

impl Default for LimbParams {
    /// A 0.6 m arm, 6 → 4 cm radius, 8 × 8 × 40 cells: 3321 nodes, 15 360 tets,
    /// 1410 surface vertices.
    fn default() -> Self {
        Self {
            length: 0.6,
            root_radius: 0.06,
            tip_radius: 0.04,
            cells_across: 8,
            cells_along: 40,
            joint: 0.5,
            bone_radius: 0.35,
            joint_gap: 0.06,
        }
    }
}

impl LimbParams {
    /// A small body for tests: 4 × 4 × 12 cells, 1152 tets; the bone takes the inner
    /// half of the radius so that it is more than the axis line at this resolution.
    pub fn quick() -> Self {
        Self {
            cells_across: 4,
            cells_along: 12,
            bone_radius: 0.5,
            ..Self::default()
        }
    }
    /// The speed-measurement body: 14 × 14 × 116 cells, whose boundary surface has
    /// exactly **6890 vertices** (SMPL's count; 4·14·117 lateral + 2·13² cap vertices)
    /// and 136 416 tets.
    pub fn smpl_resolution() -> Self {
        Self {
            cells_across: 14,
            cells_along: 116,
            ..Self::default()
        }
    }
    /// The benchmark body: 10 × 10 × 84 cells, 50 400 tets (NNWarp Table 1's ~52k).
    pub fn benchmark() -> Self {
        Self {
            cells_across: 10,
            cells_along: 84,
            ..Self::default()
        }
    }

    /// The tissue radius at `x` (m).
    pub fn radius_at(&self, x: f64) -> f64 {
        self.root_radius + (self.tip_radius - self.root_radius) * (x / self.length).clamp(0.0, 1.0)
    }
    /// The elbow's position on the axis (m).
    pub fn joint_position(&self) -> Vector3<f64> {
        Vector3::new(self.joint * self.length, 0.0, 0.0)
    }

    fn validate(&self) -> Result<()> {
        for (what, v) in [
            ("limb length", self.length),
            ("limb root radius", self.root_radius),
            ("limb tip radius", self.tip_radius),
            ("bone radius fraction", self.bone_radius),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::InvalidParameter(format!(
                    "{what} must be positive and finite, got {v}"
                )));
            }
        }
        if !(self.joint > 0.0 && self.joint < 1.0) {
            return Err(Error::InvalidParameter(format!(
                "joint fraction must lie in (0, 1), got {}",
                self.joint
            )));
        }
        if self.bone_radius >= 1.0 {
            return Err(Error::InvalidParameter(format!(
                "bone radius fraction must be below 1, got {}",
                self.bone_radius
            )));
        }
        if !(self.joint_gap.is_finite() && self.joint_gap >= 0.0) {
            return Err(Error::InvalidParameter(format!(
                "joint gap must be non-negative, got {}",
                self.joint_gap
            )));
        }
        if self.cells_across < 2 || !self.cells_across.is_multiple_of(2) || self.cells_along < 2 {
            return Err(Error::InvalidParameter(format!(
                "a limb needs an even number ≥ 2 of cells across and ≥ 2 along, got {} and {}",
                self.cells_across, self.cells_along
            )));
        }
        Ok(())
    }
}

/// A tet-meshed limb with its bone labelling.
#[derive(Debug, Clone)]
pub struct Limb {
    pub mesh: TetMesh,
    /// `bone[v]` is the bone node `v` moves rigidly with (0 = upper arm, 1 = forearm),
    /// or `None` for soft tissue.
    pub bone: Vec<Option<usize>>,
    pub params: LimbParams,
}

impl Limb {
    /// Nodes attached to bone `b`.
    pub fn bone_nodes(&self, b: usize) -> Vec<usize> {
        (0..self.bone.len()).filter(|&v| self.bone[v] == Some(b)).collect()
    }
    /// Every bone node, in index order.
    pub fn all_bone_nodes(&self) -> Vec<usize> {
        (0..self.bone.len()).filter(|&v| self.bone[v].is_some()).collect()
    }
}

/// Generates the limb of `params`.
pub fn limb(params: &LimbParams) -> Result<Limb> {
    params.validate()?;
    let n = params.cells_across;
    // A unit-spaced grid over [0, L] × [−1, 1]² mapped onto the tapered cylinder.
    let grid = beam(&BeamParams {
        cells: [params.cells_along, n, n],
        size: [params.length, 2.0, 2.0],
    })?;
    let map = |p: &Vector3<f64>| {
        let (s, t) = (p.y - 1.0, p.z - 1.0);
        let r2 = (s * s + t * t).sqrt();
        let scale = if r2 > 0.0 { s.abs().max(t.abs()) / r2 } else { 0.0 };
        let r = params.radius_at(p.x);
        Vector3::new(p.x, r * s * scale, r * t * scale)
    };
    let positions: Vec<Vector3<f64>> = grid.positions().iter().map(map).collect();
    let joint_x = params.joint * params.length;
    let tol = 1e-9 * params.length;
    let bone = positions
        .iter()
        .map(|p| {
            let radial = (p.y * p.y + p.z * p.z).sqrt();
            if p.x <= tol {
                Some(0)
            } else if radial <= params.bone_radius * params.radius_at(p.x) + tol
                && (p.x - joint_x).abs() >= 0.5 * params.joint_gap
            {
                Some(if p.x < joint_x { 0 } else { 1 })
            } else {
                None
            }
        })
        .collect();
    let mesh = TetMesh::new(positions, grid.tets().to_vec())?;
    Ok(Limb {
        mesh,
        bone,
        params: *params,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_match_the_documented_counts() {
        let quick = limb(&LimbParams::quick()).unwrap();
        assert_eq!(quick.mesh.num_tets(), 6 * 4 * 4 * 12);
        let default = limb(&LimbParams::default()).unwrap();
        assert_eq!(default.mesh.num_tets(), 15_360);
        assert_eq!(default.mesh.num_vertices(), 41 * 81);
        assert_eq!(default.mesh.boundary_surface().unwrap().mesh.num_vertices(), 1410);
        let p = LimbParams::smpl_resolution();
        // Surface count without building the 136k-tet mesh: lateral rings plus caps.
        let (n, m) = (p.cells_across, p.cells_along);
        assert_eq!(4 * n * (m + 1) + 2 * (n - 1) * (n - 1), 6890);
        let b = LimbParams::benchmark();
        assert_eq!(6 * b.cells_across * b.cells_across * b.cells_along, 50_400);
    }

    #[test]
    fn body_is_a_round_tapered_limb_with_interior_bones() {
        let l = limb(&LimbParams::default()).unwrap();
        let p = &l.params;
        let surface = l.mesh.boundary_surface().unwrap();
        let joint_x = p.joint * p.length;
        for (i, &v) in surface.volume_vertex.iter().enumerate() {
            let x = surface.mesh.positions()[i];
            let on_cap = x.x.abs() < 1e-12 || (x.x - p.length).abs() < 1e-12;
            if !on_cap {
                // Lateral surface vertices lie on the circle of the local radius.
                let r = (x.y * x.y + x.z * x.z).sqrt();
                assert!((r - p.radius_at(x.x)).abs() < 1e-12, "vertex {v} at radius {r}");
                assert!(l.bone[v].is_none(), "bone node {v} on the lateral surface");
            }
        }
        let up = l.bone_nodes(0);
        let fore = l.bone_nodes(1);
        assert!(up.len() > 81 && fore.len() > 10);
        for &v in &fore {
            assert!(l.mesh.positions()[v].x >= joint_x + 0.5 * p.joint_gap - 1e-12);
        }
        // The volume approaches that of the truncated cone as the disk map fills in.
        let cone = std::f64::consts::PI * p.length / 3.0
            * (p.root_radius.powi(2) + p.root_radius * p.tip_radius + p.tip_radius.powi(2));
        let v = l.mesh.volume();
        assert!(v < cone && v > 0.9 * cone, "volume {v} vs cone {cone}");
    }

    #[test]
    fn rejects_bad_parameters() {
        for p in [
            LimbParams {
                cells_across: 3,
                ..LimbParams::quick()
            },
            LimbParams {
                joint: 1.0,
                ..LimbParams::quick()
            },
            LimbParams {
                length: -1.0,
                ..LimbParams::quick()
            },
            LimbParams {
                bone_radius: 1.5,
                ..LimbParams::quick()
            },
        ] {
            assert!(matches!(limb(&p), Err(Error::InvalidParameter(_))), "{p:?}");
        }
    }
}
