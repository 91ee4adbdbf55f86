//! Penalty contact against a static obstacle: `E = ½ k Σ_i max(0, δ − d(x_i))²`, with
//! `d` the signed distance to the obstacle (positive outside) and `δ` a contact margin
//! (m). The energy is C¹ with a Lipschitz gradient, which is what Newton with a line
//! search needs; at rest a vertex pressed by force `f` sits `f/k` inside the margin, so
//! the *penetration tolerance* of a scene is `max(0, f_max/k − δ)` — with the defaults
//! (δ = 5 mm, k = 1e4 N/m per vertex) nothing enters the obstacle under cloth weight.
//! Only vertices are tested against the obstacle (no edge–face contact); meshes are fine
//! enough in weft's scenes for that to hold.
//!
//! A triangle-mesh query is the expensive part (a bounding-volume traversal per vertex;
//! a quarter of the loose sleeve's drape solve before the clearances below). Each vertex
//! keeps the last place it was queried at and its distance there; by the triangle
//! inequality, a vertex that has moved less than that distance minus the margin is still
//! outside and farther than the margin, so it adds nothing and is not queried again. The
//! answers are exactly those of querying every vertex every time, for the closed,
//! outward-oriented meshes an obstacle must be (a point cannot change sides without
//! crossing the surface).

use std::sync::{Mutex, PoisonError};

use nalgebra::{Matrix3, Vector3};
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::PointQueryWithLocation;
use parry3d_f64::shape::{TriMesh as ParryMesh, TriMeshFlags, TrianglePointLocation};
use weft_linalg::SymmetricMatrix;

use crate::energy::{Energy, vertex};
use crate::error::{Error, Result, check_nonnegative, check_positive};

/// The shape of a static obstacle.
#[derive(Debug, Clone)]
pub enum ObstacleShape {
    Sphere {
        center: Vector3<f64>,
        radius: f64,
    },
    /// Half-space `{x : (x − point) · normal ≤ 0}` is solid; `normal` points out of it.
    Plane {
        point: Vector3<f64>,
        normal: Vector3<f64>,
    },
    /// A closed, outward-oriented triangle mesh.
    Mesh(Box<ParryMesh>),
}

/// Closest-feature query: signed distance, outward normal and the curvature `∇²d`
/// (zero where the closest feature is flat).
struct Contact {
    distance: f64,
    normal: Vector3<f64>,
    curvature: Matrix3<f64>,
}

impl ObstacleShape {
    /// A triangle-mesh obstacle from weft's mesh (must be closed and outward-oriented for
    /// inside/outside to be meaningful).
    pub fn mesh(mesh: &weft_mesh::TriMesh) -> Result<Self> {
        let vertices = mesh.positions().iter().map(|p| PVec::new(p.x, p.y, p.z)).collect();
        let indices = mesh.faces().iter().map(|f| f.map(|v| v as u32)).collect();
        let m = ParryMesh::with_flags(vertices, indices, TriMeshFlags::ORIENTED)
            .map_err(|e| Error::Scene(format!("obstacle mesh rejected by parry3d: {e:?}")))?;
        Ok(Self::Mesh(Box::new(m)))
    }

    fn contact(&self, x: &Vector3<f64>) -> Contact {
        match self {
            Self::Sphere { center, radius } => {
                let r = x - center;
                let l = r.norm();
                if l < 1e-12 * radius.max(1.0) {
                    return Contact {
                        distance: -radius,
                        normal: Vector3::z(),
                        curvature: Matrix3::zeros(),
                    };
                }
                let n = r / l;
                Contact {
                    distance: l - radius,
                    normal: n,
                    curvature: (Matrix3::identity() - n * n.transpose()) / l,
                }
            }
            Self::Plane { point, normal } => Contact {
                distance: (x - point).dot(normal),
                normal: *normal,
                curvature: Matrix3::zeros(),
            },
            Self::Mesh(m) => {
                let q = PVec::new(x.x, x.y, x.z);
                let (proj, (tri, loc)) = m.project_local_point_and_get_location(q, false);
                let p = Vector3::new(proj.point.x, proj.point.y, proj.point.z);
                let d = x - p;
                let l = d.norm();
                let sign = if proj.is_inside { -1.0 } else { 1.0 };
                let face_normal = || {
                    let t = m.triangle(tri);
                    let n = (t.b - t.a).cross(t.c - t.a).normalize();
                    Vector3::new(n.x, n.y, n.z)
                };
                if l < 1e-12 {
                    return Contact {
                        distance: 0.0,
                        normal: face_normal(),
                        curvature: Matrix3::zeros(),
                    };
                }
                let n = sign * d / l;
                // Closest feature a vertex: d is the distance to a point (sphere-like
                // curvature). On a face: flat. On an edge: curvature only across the edge
                // (Gauss–Newton there: the across-edge term is dropped).
                let curvature = match loc {
                    TrianglePointLocation::OnVertex(_) => sign * (Matrix3::identity() - n * n.transpose()) / l,
                    _ => Matrix3::zeros(),
                };
                Contact {
                    distance: sign * l,
                    normal: n,
                    curvature,
                }
            }
        }
    }
}

fn check_finite_point(name: &'static str, p: &Vector3<f64>) -> Result<()> {
    match p.iter().find(|c| !c.is_finite()) {
        Some(&value) => Err(Error::InvalidParameter {
            name,
            value,
            reason: "every coordinate must be finite",
        }),
        None => Ok(()),
    }
}

/// A place `anchor` (m) outside the obstacle and at least `distance` (m) from it.
#[derive(Debug, Clone, Copy)]
struct Clearance {
    anchor: Vector3<f64>,
    distance: f64,
}

/// Rounding allowance (m) of a clearance test: parry's distance and the displacement's
/// norm are each within a few ulps of 1 m at most, far below this.
const CLEARANCE_SLACK: f64 = 1e-12;

/// Penalty contact energy of all vertices against one obstacle.
#[derive(Debug)]
pub struct ObstaclePenalty {
    shape: ObstacleShape,
    stiffness: f64,
    margin: f64,
    num_vertices: usize,
    /// Per vertex, where it was last queried outside a mesh obstacle (see the module
    /// documentation); only ever a true bound, so the state never changes an answer.
    clearances: Mutex<Vec<Option<Clearance>>>,
}

impl Clone for ObstaclePenalty {
    fn clone(&self) -> Self {
        Self {
            shape: self.shape.clone(),
            stiffness: self.stiffness,
            margin: self.margin,
            num_vertices: self.num_vertices,
            clearances: Mutex::new(vec![None; self.num_vertices]),
        }
    }
}

impl ObstaclePenalty {
    /// `stiffness` k (N/m per vertex), `margin` δ (m).
    pub fn new(shape: ObstacleShape, num_vertices: usize, stiffness: f64, margin: f64) -> Result<Self> {
        check_positive("obstacle stiffness (N/m)", stiffness)?;
        check_nonnegative("obstacle margin (m)", margin)?;
        if let ObstacleShape::Sphere { radius, center } = &shape {
            check_positive("sphere radius (m)", *radius)?;
            check_finite_point("sphere centre", center)?;
        }
        if let ObstacleShape::Plane { point, normal } = &shape {
            // A NaN point or normal would make every distance NaN, every `φ > 0` test
            // false, and so silently switch the obstacle off.
            check_finite_point("plane point", point)?;
            check_finite_point("plane normal", normal)?;
        }
        if let ObstacleShape::Plane { normal, .. } = &shape {
            if !(normal.norm() > 0.0) {
                return Err(Error::InvalidParameter {
                    name: "plane normal length",
                    value: normal.norm(),
                    reason: "must be non-zero",
                });
            }
        }
        let shape = match shape {
            ObstacleShape::Plane { point, normal } => ObstacleShape::Plane {
                point,
                normal: normal.normalize(),
            },
            s => s,
        };
        Ok(Self {
            shape,
            stiffness,
            margin,
            num_vertices,
            clearances: Mutex::new(vec![None; num_vertices]),
        })
    }

    /// The contact of the vertex `i` at `x`, or `None` when it is outside and farther
    /// than the margin (it then adds nothing to the energy or its derivatives).
    fn contact_within_margin(
        &self,
        clearances: &mut [Option<Clearance>],
        i: usize,
        x: &Vector3<f64>,
    ) -> Option<Contact> {
        let ObstacleShape::Mesh(_) = self.shape else {
            let c = self.shape.contact(x);
            return (self.margin - c.distance > 0.0).then_some(c);
        };
        if let Some(c) = clearances[i] {
            // d(x) ≥ d(anchor) − |x − anchor|, and every point of the segment from the
            // anchor to x is at least that far from the surface, so x is outside too.
            if c.distance - (x - c.anchor).norm() > self.margin + CLEARANCE_SLACK {
                return None;
            }
        }
        let c = self.shape.contact(x);
        clearances[i] = (c.distance > 0.0).then_some(Clearance {
            anchor: *x,
            distance: c.distance,
        });
        (self.margin - c.distance > 0.0).then_some(c)
    }

    /// The per-vertex clearances, for one evaluation (a poisoned lock still holds true
    /// bounds: each entry is written whole).
    fn clearances(&self) -> std::sync::MutexGuard<'_, Vec<Option<Clearance>>> {
        self.clearances.lock().unwrap_or_else(PoisonError::into_inner)
    }

    pub fn shape(&self) -> &ObstacleShape {
        &self.shape
    }

    /// Signed distance of a point to the obstacle surface (m, positive outside).
    pub fn signed_distance(&self, x: &Vector3<f64>) -> f64 {
        self.shape.contact(x).distance
    }
}

impl Energy for ObstaclePenalty {
    fn name(&self) -> &'static str {
        "obstacle"
    }
    fn num_dofs(&self) -> Option<usize> {
        Some(3 * self.num_vertices)
    }
    fn hessian_pairs(&self, _pairs: &mut Vec<(usize, usize)>) {}
    fn value(&self, x: &[f64]) -> f64 {
        let mut clearances = self.clearances();
        (0..self.num_vertices)
            .map(
                |i| match self.contact_within_margin(&mut clearances, i, &vertex(x, i)) {
                    Some(c) => {
                        let phi = self.margin - c.distance;
                        0.5 * self.stiffness * phi * phi
                    }
                    None => 0.0,
                },
            )
            .sum()
    }
    fn add_gradient(&self, x: &[f64], grad: &mut [f64]) {
        let mut clearances = self.clearances();
        for i in 0..self.num_vertices {
            if let Some(c) = self.contact_within_margin(&mut clearances, i, &vertex(x, i)) {
                let phi = self.margin - c.distance;
                // ∇E = k φ ∇φ = −k φ n.
                for k in 0..3 {
                    grad[3 * i + k] -= self.stiffness * phi * c.normal[k];
                }
            }
        }
    }
    fn add_hessian(&self, x: &[f64], project: bool, hessian: &mut SymmetricMatrix) {
        let mut clearances = self.clearances();
        for i in 0..self.num_vertices {
            if let Some(c) = self.contact_within_margin(&mut clearances, i, &vertex(x, i)) {
                let phi = self.margin - c.distance;
                // ∇²E = k (n nᵀ − φ ∇²d). Outside a convex feature ∇²d is PSD, so the
                // second term is negative: projection drops it.
                let mut h = self.stiffness * c.normal * c.normal.transpose();
                let curv = -self.stiffness * phi * c.curvature;
                if !project || curv.symmetric_eigenvalues().iter().all(|&l| l >= 0.0) {
                    h += curv;
                }
                for a in 0..3 {
                    for b in 0..3 {
                        hessian.add(3 * i + a, 3 * i + b, h[(a, b)]);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use weft_linalg::SymmetricPattern;
    use weft_mesh::generators;
    use weft_testkit::TestRng;

    use super::*;

    /// Value, gradient and Hessian (dense), each from `e` as it is.
    fn evaluate(e: &ObstaclePenalty, x: &[f64]) -> (f64, Vec<f64>, Vec<f64>) {
        let mut grad = vec![0.0; x.len()];
        e.add_gradient(x, &mut grad);
        let n = x.len() / 3;
        let pattern = Arc::new(SymmetricPattern::from_vertex_pairs(n, Vec::new()));
        let mut h = SymmetricMatrix::zeros(pattern);
        e.add_hessian(x, true, &mut h);
        let dense = (0..x.len())
            .flat_map(|r| (0..x.len()).map(move |c| (r, c)))
            .map(|(r, c)| h.get(r, c))
            .collect();
        (e.value(x), grad, dense)
    }

    #[test]
    fn remembered_clearances_never_change_an_answer_and_spare_far_queries() {
        // The unit cube's surface; vertices wander in and out of the margin and through
        // the box, in small steps and in jumps.
        let cube = generators::beam(&generators::BeamParams {
            cells: [1, 1, 1],
            size: [1.0, 1.0, 1.0],
        })
        .unwrap()
        .boundary_surface()
        .unwrap()
        .mesh;
        let n = 24;
        let margin = 0.05;
        let e = ObstaclePenalty::new(ObstacleShape::mesh(&cube).unwrap(), n, 1e3, margin).unwrap();
        let mut rng = TestRng::new(31);
        let mut x = rng.vec(3 * n, -0.5, 1.5);
        let (mut skipped, mut in_contact) = (0, 0);
        for step in 0..300 {
            let jump = if step % 37 == 0 { 0.5 } else { 0.02 };
            for v in &mut x {
                *v = (*v + rng.uniform(-jump, jump)).clamp(-0.6, 1.6);
            }
            // A clone starts with no clearances: every vertex queried afresh.
            let (fresh, remembered) = (evaluate(&e.clone(), &x), evaluate(&e, &x));
            assert_eq!(fresh.0.to_bits(), remembered.0.to_bits(), "value at step {step}");
            assert_eq!(fresh.1, remembered.1, "gradient at step {step}");
            assert_eq!(fresh.2, remembered.2, "Hessian at step {step}");
            let clearances = e.clearances();
            for i in 0..n {
                let p = vertex(&x, i);
                let d = e.signed_distance(&p);
                in_contact += usize::from(d < margin);
                skipped += usize::from(clearances[i].is_some_and(|c| c.anchor != p));
            }
        }
        // Both kinds of vertex were seen: some spared a query, some in contact.
        assert!(
            skipped > 1000,
            "{skipped} vertex evaluations used a remembered clearance"
        );
        assert!(in_contact > 100, "{in_contact} vertex evaluations were in contact");
    }
}
