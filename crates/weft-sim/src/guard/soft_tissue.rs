//! The guard on the soft-tissue limb (volumetric, tet FEM; docs/GUARD.md, "limb-jiggle"):
//! the guarded frame of a [`SoftTissue`] sequence, and the limb's surrogates.
//!
//! The limb family's models predict the **surface** (the skinned surface `X_t`, the
//! learned `Y_t`), while the step's residual needs every node. [`InteriorCompletion`]
//! fills in the interior nodes from the surface and the bones by a harmonic extension of
//! the displacement — the P1 Laplacian of the rest mesh, factorised once, one solve per
//! proposal — as issue 73 asks ("complete the rest cheaply before the residual").
//! [`SkinningCompleted`] is the limb family's baseline so completed.

use std::sync::Arc;

use nalgebra::Vector3;
use weft_linalg::{CholeskyFactor, CholeskySolver, SymmetricMatrix, SymmetricPattern};

use super::{GuardReport, StepInput, Surrogate, SurrogateError};
use crate::error::Result;
use crate::scenes::soft_tissue::{SkeletalMotion, SoftTissue, SoftTissueParams, blend, substep_time};

/// One guarded frame of a soft-tissue sequence ([`SoftTissue::step_frame_guarded`]): the
/// guard's report of each implicit-Euler substep, in order.
#[derive(Debug, Clone)]
pub struct GuardedTissueFrame {
    pub reports: Vec<GuardReport>,
    /// Wall time of the frame (s).
    pub seconds: f64,
}

impl GuardedTissueFrame {
    /// Newton iterations over the frame's substeps.
    pub fn newton_iterations(&self) -> usize {
        self.reports.iter().map(|r| r.newton_iterations).sum()
    }
}

/// The harmonic extension of a displacement from held nodes (the surface and the bones)
/// to the rest of a tet mesh: the interior displacement `d_I` solves
///
/// ```text
/// L_II d_I = −L_IH d_H,      L_ab = Σ_tets V ∇φ_a · ∇φ_b                         (G8)
/// ```
///
/// per coordinate, with `L` the P1 (piecewise-linear FEM) Laplacian of the rest mesh and
/// `φ` the hat functions. `L` annihilates every linear field at interior nodes, so an
/// affine map of the rest mesh (a rigid motion of the whole limb) is reproduced exactly.
/// `L_II` is factorised once at construction (weft-linalg's sparse Cholesky); a
/// completion is one solve with three right-hand sides.
#[derive(Debug, Clone)]
pub struct InteriorCompletion {
    rest: Vec<f64>,
    /// The interior nodes, in the factor's numbering.
    interior: Vec<usize>,
    /// `(interior row, held node, L_ih)`.
    coupling: Vec<(usize, usize, f64)>,
    factor: CholeskyFactor,
}

impl InteriorCompletion {
    /// The completion of the tet mesh (`rest` positions, `tets`) with the nodes where
    /// `held` is true given.
    pub fn new(rest: &[Vector3<f64>], tets: &[[usize; 4]], held: &[bool]) -> Result<Self> {
        assert_eq!(held.len(), rest.len(), "held-node mask length");
        let inverses = weft_mesh::geometry::tet_rest_inverses(rest, tets)?;
        let volumes = weft_mesh::geometry::tet_volumes(rest, tets);
        let mut index = vec![usize::MAX; rest.len()];
        let interior: Vec<usize> = (0..rest.len()).filter(|&v| !held[v]).collect();
        for (i, &v) in interior.iter().enumerate() {
            index[v] = i;
        }
        // Element Laplacians: ∇φ_j is row j of D_m⁻¹ (j = 1..3), ∇φ_0 = −Σ_j ∇φ_j.
        let elements: Vec<([usize; 4], [[f64; 4]; 4])> = tets
            .iter()
            .zip(&inverses)
            .zip(&volumes)
            .map(|((t, inv), vol)| {
                let mut g = [Vector3::zeros(); 4];
                for j in 0..3 {
                    g[j + 1] = inv.row(j).transpose();
                }
                g[0] = -(g[1] + g[2] + g[3]);
                let mut k = [[0.0; 4]; 4];
                for a in 0..4 {
                    for b in 0..4 {
                        k[a][b] = vol.abs() * g[a].dot(&g[b]);
                    }
                }
                (*t, k)
            })
            .collect();
        let pairs = elements.iter().flat_map(|(t, _)| {
            let index = &index;
            (0..4).flat_map(move |a| (0..4).map(move |b| (index[t[a]], index[t[b]])))
        });
        let pattern = Arc::new(SymmetricPattern::new(
            interior.len(),
            pairs.filter(|&(i, j)| i != usize::MAX && j != usize::MAX),
        ));
        let mut matrix = SymmetricMatrix::zeros(pattern.clone());
        let mut coupling = Vec::new();
        for (t, k) in &elements {
            for a in 0..4 {
                let i = index[t[a]];
                if i == usize::MAX {
                    continue;
                }
                for b in 0..4 {
                    match index[t[b]] {
                        usize::MAX => coupling.push((i, t[b], k[a][b])),
                        // The pattern stores the upper triangle; add each pair once.
                        j if j >= i => matrix.add(i, j, k[a][b]),
                        _ => {}
                    }
                }
            }
        }
        let factor = CholeskySolver::new(pattern)?.factorize(&matrix)?;
        Ok(Self {
            rest: weft_mesh::flatten(rest),
            interior,
            coupling,
            factor,
        })
    }

    /// The completion for `tissue`'s mesh: its boundary surface and bone nodes held.
    pub fn for_tissue(tissue: &SoftTissue) -> Result<Self> {
        let mesh = &tissue.limb().mesh;
        let mut held = vec![false; mesh.num_vertices()];
        for &v in &tissue.surface().volume_vertex {
            held[v] = true;
        }
        for v in tissue.limb().all_bone_nodes() {
            held[v] = true;
        }
        Self::new(mesh.positions(), mesh.tets(), &held)
    }

    /// Overwrites the interior nodes of `x` (flat, m) by the harmonic extension (Eq. G8)
    /// of the held nodes' displacement from rest.
    pub fn complete(&self, x: &mut [f64]) {
        let n = self.interior.len();
        let mut rhs = vec![0.0; 3 * n];
        for &(i, h, l) in &self.coupling {
            for a in 0..3 {
                rhs[a * n + i] -= l * (x[3 * h + a] - self.rest[3 * h + a]);
            }
        }
        self.factor.solve_many_in_place(&mut rhs, 3);
        for (i, &v) in self.interior.iter().enumerate() {
            for a in 0..3 {
                x[3 * v + a] = self.rest[3 * v + a] + rhs[a * n + i];
            }
        }
    }
}

/// The limb family's baseline as a surrogate: the linear-blend-skinned surface `X_t`
/// (`SoftTissue::skinned_surface`) at the step's time, the bones at their prescribed
/// positions, and the interior completed by [`InteriorCompletion`]. It predicts no
/// dynamics: its error is the tissue's lag, sag and jiggle about the skin.
#[derive(Debug, Clone)]
pub struct SkinningCompleted {
    params: SoftTissueParams,
    motion: SkeletalMotion,
    elbow: Vector3<f64>,
    rest: Vec<Vector3<f64>>,
    forearm_weight: Vec<f64>,
    /// The surface's nodes in the tet mesh.
    surface: Vec<usize>,
    completion: Arc<InteriorCompletion>,
}

impl SkinningCompleted {
    /// The surrogate of `tissue`'s sequence (its motion, mesh and timing), with its
    /// completion factorised here.
    pub fn new(tissue: &SoftTissue) -> Result<Self> {
        Ok(Self::with_completion(
            tissue,
            Arc::new(InteriorCompletion::for_tissue(tissue)?),
        ))
    }

    /// As [`SkinningCompleted::new`], sharing an existing factorisation of `tissue`'s mesh.
    pub fn with_completion(tissue: &SoftTissue, completion: Arc<InteriorCompletion>) -> Self {
        Self {
            params: *tissue.params(),
            motion: tissue.motion().clone(),
            elbow: tissue.limb().params.joint_position(),
            rest: tissue.limb().mesh.positions().to_vec(),
            forearm_weight: tissue.forearm_weights().to_vec(),
            surface: tissue.surface().volume_vertex.clone(),
            completion,
        }
    }
}

impl Surrogate for SkinningCompleted {
    fn name(&self) -> &str {
        "skinning-completed"
    }
    fn num_dofs(&self) -> usize {
        3 * self.rest.len()
    }
    fn dt(&self) -> Option<f64> {
        Some(self.params.frame_dt / self.params.substeps as f64)
    }
    fn propose(&mut self, input: &StepInput<'_>) -> Result<Vec<f64>, SurrogateError> {
        // Step s ≥ 1 is substep k of the frame after frame f (SoftTissue::step_frame_with).
        let s = input.frame.max(1) - 1;
        let (f, k) = (s / self.params.substeps, s % self.params.substeps + 1);
        let transforms = self
            .motion
            .bone_transforms(substep_time(&self.params, f, k), &self.elbow);
        let mut x = input.current.to_vec();
        for &v in &self.surface {
            let p = blend(&self.rest[v], self.forearm_weight[v], &transforms);
            x[3 * v..3 * v + 3].copy_from_slice(p.as_slice());
        }
        for &(dof, value) in input.prescribed {
            x[dof] = value;
        }
        self.completion.complete(&mut x);
        Ok(x)
    }
}
