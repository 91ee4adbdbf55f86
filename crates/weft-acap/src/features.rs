//! The ACAP feature extractor (Tan et al. §III-A, Eq. 1; docs/ACAP.md §A1–§A4).

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use weft_mesh::{Topology, TriMesh, geometry};

use crate::consistency::{ConsistencyReport, consistent_logs};
use crate::error::{Error, Result};
use crate::rings::Rings;
use crate::rotation::{polar_decomposition, principal_log};

/// One vertex's ACAP feature: the log-rotation as the upper triangle of `K = [r]_×`,
/// `(K₁₂, K₁₃, K₂₃) = (−r_z, r_y, −r_x)`, then the upper triangle of the symmetric
/// stretch, `(S₁₁, S₁₂, S₁₃, S₂₂, S₂₃, S₃₃)` (docs/ACAP.md §A4, the release's `FeatureMap.m`).
pub type Feature = [f64; 9];

/// Indices of the log-rotation block in a [`Feature`].
pub const LOG_ROTATION_BLOCK: std::ops::Range<usize> = 0..3;
/// Indices of the stretch block in a [`Feature`].
pub const STRETCH_BLOCK: std::ops::Range<usize> = 3..9;

/// Packs a log-rotation vector and a symmetric stretch into a [`Feature`].
pub fn feature_from_parts(log_rotation: &Vector3<f64>, stretch: &Matrix3<f64>) -> Feature {
    let (r, s) = (log_rotation, stretch);
    [
        -r.z,
        r.y,
        -r.x,
        s[(0, 0)],
        s[(0, 1)],
        s[(0, 2)],
        s[(1, 1)],
        s[(1, 2)],
        s[(2, 2)],
    ]
}

/// The log-rotation vector r of a [`Feature`].
pub fn feature_log_rotation(f: &Feature) -> Vector3<f64> {
    Vector3::new(-f[2], f[1], -f[0])
}

/// The symmetric stretch S of a [`Feature`].
pub fn feature_stretch(f: &Feature) -> Matrix3<f64> {
    Matrix3::new(f[3], f[4], f[5], f[4], f[6], f[7], f[5], f[7], f[8])
}

/// How the 1-ring edges are weighted, in Eq. 1 and in the Poisson system alike (the same
/// weights on both sides keep the round trip tight, docs/ACAP.md §A5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[non_exhaustive]
pub enum EdgeWeights {
    /// The release's positive cotangent weights `w = sqrt(sexp(c))`, `c = ½(cot α + cot β)`,
    /// `sexp(x) = eˣ (x ≤ 0), 1 + x (x > 0)`; NaN or > 1e5 → 1 (docs/ACAP.md §A1).
    ReleaseCotangent,
    /// `w = sexp(c)` without the square root: the closest positive stand-in for the
    /// cotangent weights, and the smallest round-trip error of the three (docs/ACAP.md).
    #[default]
    PositiveCotangent,
    /// `w = 1`.
    Uniform,
}

/// Settings of the feature extractor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AcapSettings {
    pub edge_weights: EdgeWeights,
    /// Length of the extra normal pair as a multiple of the vertex's mean 1-ring edge
    /// length. Must be positive: it is what keeps flat 1-rings well posed. On a flat rest
    /// 1-ring its value does not matter (T n_q = (h_p/h_q) n_p whatever the scale); on a
    /// curved one a smaller pair biases the edge fit less. The release uses 0.3; weft's
    /// default 0.1 cuts the ball's round-trip error by ~40 % (docs/ACAP.md §2, §6).
    pub normal_scale: f64,
}

impl Default for AcapSettings {
    fn default() -> Self {
        Self {
            edge_weights: EdgeWeights::PositiveCotangent,
            normal_scale: 0.1,
        }
    }
}

/// The ACAP feature extractor of one rest mesh: cotangent weights, inverse rest edge
/// covariances and 1-ring lists, computed once; [`AcapFeatures::encode`] per frame.
///
/// Per vertex i, with rest edges e_ij = q_j − q_i and deformed edges d_ij = p_j − p_i
/// (Tan et al. Eq. 1, docs/ACAP.md §A1):
///
/// `T_i = (Σ_j w_ij d_ij e_ijᵀ + h_p h_q n_p n_qᵀ) (Σ_j w_ij e_ij e_ijᵀ + h_q² n_q n_qᵀ)⁻¹`
///
/// where n_q, n_p are the rest and deformed vertex normals and h = `normal_scale` × the
/// mean 1-ring edge length of that mesh. On a flat 1-ring the edge covariance is rank 2;
/// the normal pair makes it full rank and makes T map the rest normal to the deformed one.
#[derive(Debug, Clone)]
pub struct AcapFeatures {
    settings: AcapSettings,
    rest: Vec<Vector3<f64>>,
    faces: Vec<[usize; 3]>,
    rest_face_areas: Vec<f64>,
    rings: Rings,
    rest_normal_terms: Vec<Vector3<f64>>,
    rest_covariance_inverses: Vec<Matrix3<f64>>,
    roots: Vec<usize>,
}

/// A face whose area falls to this fraction of its rest area counts as collapsed.
const COLLAPSED_AREA_RATIO: f64 = 1e-12;

impl AcapFeatures {
    /// Precomputes everything that depends on the rest mesh only.
    pub fn new(rest: &TriMesh, settings: AcapSettings) -> Result<Self> {
        if !(settings.normal_scale.is_finite() && settings.normal_scale > 0.0) {
            return Err(Error::InvalidSettings(format!(
                "normal_scale must be positive and finite (it keeps flat 1-rings well posed), got {}",
                settings.normal_scale
            )));
        }
        let q = rest.positions();
        let faces = rest.faces();
        let areas = geometry::face_areas(q, faces);
        let mean_area = areas.iter().sum::<f64>() / areas.len() as f64;
        for (face, &area) in areas.iter().enumerate() {
            if area.is_nan() || area <= 1e-12 * mean_area {
                return Err(Error::DegenerateRestFace { face, area });
            }
        }
        let topology = Topology::new(rest);
        let cot = geometry::cotangent_weights(q, faces, &topology)?;
        let edge_weight: Vec<f64> = cot.iter().map(|&c| edge_weight(settings.edge_weights, c)).collect();

        let n = q.len();
        let rings = Rings::new(&topology, &edge_weight);

        let normals = geometry::vertex_normals(q, faces);
        let mut rest_normal_terms = Vec::with_capacity(n);
        let mut rest_covariance_inverses = Vec::with_capacity(n);
        for i in 0..n {
            let nb = rings.neighbors(i);
            if nb.is_empty() || normals[i] == Vector3::zeros() {
                return Err(Error::DegenerateOneRing { vertex: i });
            }
            let h = settings.normal_scale * mean_edge_length(q, i, nb);
            let nq = normals[i] * h;
            let mut c = nq * nq.transpose();
            for (&j, &w) in nb.iter().zip(rings.weights(i)) {
                let e = q[j] - q[i];
                c += e * e.transpose() * w;
            }
            let scale = c.trace() / 3.0;
            let det = c.determinant();
            if det.is_nan() || det <= 1e-12 * scale * scale * scale {
                return Err(Error::DegenerateOneRing { vertex: i });
            }
            let inv = c.try_inverse().ok_or(Error::DegenerateOneRing { vertex: i })?;
            rest_normal_terms.push(nq);
            rest_covariance_inverses.push(inv);
        }
        let roots = rings.component_roots();
        Ok(Self {
            settings,
            rest: q.to_vec(),
            faces: faces.to_vec(),
            rest_face_areas: areas,
            rings,
            rest_normal_terms,
            rest_covariance_inverses,
            roots,
        })
    }

    pub fn settings(&self) -> &AcapSettings {
        &self.settings
    }
    pub fn num_vertices(&self) -> usize {
        self.rest.len()
    }
    pub fn rest_positions(&self) -> &[Vector3<f64>] {
        &self.rest
    }
    pub fn faces(&self) -> &[[usize; 3]] {
        &self.faces
    }
    pub(crate) fn rings(&self) -> &Rings {
        &self.rings
    }
    /// The vertex each connected component's consistency propagation starts from.
    pub fn component_roots(&self) -> &[usize] {
        &self.roots
    }

    /// Checks a deformed frame: length, finiteness, no collapsed faces.
    fn check_frame(&self, p: &[Vector3<f64>]) -> Result<()> {
        if p.len() != self.rest.len() {
            return Err(Error::LengthMismatch {
                what: "deformed positions",
                expected: self.rest.len(),
                got: p.len(),
            });
        }
        if let Some((vertex, v)) = p.iter().enumerate().find(|(_, v)| !v.iter().all(|c| c.is_finite())) {
            return Err(Error::NonFinitePosition {
                vertex,
                x: v.x,
                y: v.y,
                z: v.z,
            });
        }
        for (face, (f, &rest_area)) in self.faces.iter().zip(&self.rest_face_areas).enumerate() {
            let area = geometry::triangle_area(&p[f[0]], &p[f[1]], &p[f[2]]);
            if area.is_nan() || area <= COLLAPSED_AREA_RATIO * rest_area {
                return Err(Error::CollapsedFace { face, area, rest_area });
            }
        }
        Ok(())
    }

    /// The per-vertex deformation gradients T_i of a deformed frame (Tan et al. Eq. 1 with
    /// the normal pair of docs/ACAP.md §A1).
    pub fn deformation_gradients(&self, p: &[Vector3<f64>]) -> Result<Vec<Matrix3<f64>>> {
        self.check_frame(p)?;
        let normals = geometry::vertex_normals(p, &self.faces);
        if let Some(vertex) = normals.iter().position(|n| *n == Vector3::zeros()) {
            return Err(Error::DegenerateDeformedOneRing { vertex });
        }
        let q = &self.rest;
        Ok((0..q.len())
            .into_par_iter()
            .with_min_len(256)
            .map(|i| {
                let nb = self.rings.neighbors(i);
                let h = self.settings.normal_scale * mean_edge_length(p, i, nb);
                let mut m = (normals[i] * h) * self.rest_normal_terms[i].transpose();
                for (&j, &w) in nb.iter().zip(self.rings.weights(i)) {
                    m += (p[j] - p[i]) * (q[j] - q[i]).transpose() * w;
                }
                m * self.rest_covariance_inverses[i]
            })
            .collect())
    }

    /// The ACAP features of one frame (Tan et al. §III-A): `(log R_i, S_i)` per vertex with
    /// `T_i = R_i S_i` and the log-rotations made consistent across neighbours.
    pub fn encode(&self, p: &[Vector3<f64>]) -> Result<Vec<Feature>> {
        Ok(self.encode_with_report(p, None)?.0)
    }

    /// [`AcapFeatures::encode`] with the consistency pass's report. `reference` (the
    /// previous frame's features) seeds each component root's log-rotation so that a
    /// sequence does not jump when the root's rotation angle passes π (docs/ACAP.md §A3 step 4).
    pub fn encode_with_report(
        &self,
        p: &[Vector3<f64>],
        reference: Option<&[Feature]>,
    ) -> Result<(Vec<Feature>, ConsistencyReport)> {
        if let Some(r) = reference
            && r.len() != self.rest.len()
        {
            return Err(Error::LengthMismatch {
                what: "reference features",
                expected: self.rest.len(),
                got: r.len(),
            });
        }
        let t = self.deformation_gradients(p)?;
        let polar: Vec<(Matrix3<f64>, Matrix3<f64>)> = t
            .par_iter()
            .with_min_len(256)
            .enumerate()
            .map(|(vertex, t)| polar_decomposition(t).ok_or(Error::PolarDecomposition { vertex }))
            .collect::<Result<_>>()?;
        let principal: Vec<(Vector3<f64>, f64)> = polar.iter().map(|(r, _)| principal_log(r)).collect();
        let reference_logs: Option<Vec<Vector3<f64>>> = reference.map(|r| r.iter().map(feature_log_rotation).collect());
        let (logs, report) = consistent_logs(&principal, &self.rings, &self.roots, reference_logs.as_deref());
        let features = logs
            .iter()
            .zip(&polar)
            .map(|(r, (_, s))| feature_from_parts(r, s))
            .collect();
        Ok((features, report))
    }

    /// Encodes independent frames in parallel (rayon); each frame's roots start at k = 0.
    pub fn encode_batch<P: AsRef<[Vector3<f64>]> + Sync>(&self, frames: &[P]) -> Result<Vec<Vec<Feature>>> {
        frames.par_iter().map(|p| self.encode(p.as_ref())).collect()
    }

    /// Encodes a time sequence in order, seeding each frame's roots from the previous
    /// frame so the features stay continuous in time (docs/ACAP.md §A3 step 4).
    pub fn encode_sequence<P: AsRef<[Vector3<f64>]>>(&self, frames: &[P]) -> Result<Vec<Vec<Feature>>> {
        let mut out: Vec<Vec<Feature>> = Vec::with_capacity(frames.len());
        for p in frames {
            let (f, _) = self.encode_with_report(p.as_ref(), out.last().map(Vec::as_slice))?;
            out.push(f);
        }
        Ok(out)
    }
}

fn mean_edge_length(p: &[Vector3<f64>], i: usize, nb: &[usize]) -> f64 {
    nb.iter().map(|&j| (p[j] - p[i]).norm()).sum::<f64>() / nb.len() as f64
}

/// Positive edge weight from the cotangent weight `c` (docs/ACAP.md §A1).
fn edge_weight(kind: EdgeWeights, c: f64) -> f64 {
    let sexp = |x: f64| if x <= 0.0 { x.exp() } else { 1.0 + x };
    let w = match kind {
        EdgeWeights::ReleaseCotangent => sexp(c).sqrt(),
        EdgeWeights::PositiveCotangent => sexp(c),
        EdgeWeights::Uniform => 1.0,
    };
    if w.is_nan() || w > 1e5 { 1.0 } else { w }
}
