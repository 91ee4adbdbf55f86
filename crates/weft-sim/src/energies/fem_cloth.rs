//! FEM cloth (Tan et al. Fig. 1d, after Narain, Samii & O'Brien 2012): a linear-elastic
//! membrane on each triangle and a quadratic dihedral-angle bending penalty on each hinge.

use nalgebra::{Matrix2, Matrix3x2, SMatrix, SVector};
use rayon::prelude::*;
use weft_linalg::SymmetricMatrix;
use weft_mesh::{Topology, TriMesh};

use super::dual::{Dual, Real, V3};
use crate::energy::{Energy, element_pairs, project_psd, scatter_gradient, scatter_hessian, vertex};
use crate::error::{Error, Result, check_nonnegative};

/// Linear-elastic membrane: per triangle `A · Ψ(E)` with the Green–Lagrange strain
/// `E = ½(FᵀF − I)` of the 3×2 deformation gradient `F = D_s D_m⁻¹` and the isotropic
/// linear stress–strain law `Ψ = μ‖E‖²_F + ½λ(tr E)²` (a Saint-Venant–Kirchhoff
/// membrane: linear in strain, exact under rotation). `μ`, `λ` are the 2-D Lamé
/// parameters (N/m) from the 2-D Young's modulus `Y` (N/m) and Poisson ratio `ν`:
/// `μ = Y / (2(1+ν))`, `λ = Yν / (1 − ν²)` (plane stress).
#[derive(Debug, Clone)]
pub struct Membrane {
    faces: Vec<[usize; 3]>,
    /// `D_m⁻¹` in each triangle's own 2-D rest frame.
    rest_inverse: Vec<Matrix2<f64>>,
    area: Vec<f64>,
    mu: f64,
    lambda: f64,
}

impl Membrane {
    pub fn new(mesh: &TriMesh, young_2d: f64, poisson: f64) -> Result<Self> {
        check_nonnegative("membrane Young's modulus (N/m)", young_2d)?;
        if !(0.0..0.5).contains(&poisson) {
            return Err(Error::InvalidParameter {
                name: "membrane Poisson ratio",
                value: poisson,
                reason: "must be in [0, 0.5)",
            });
        }
        mesh.check_face_areas(0.0)?;
        let p = mesh.positions();
        let mut rest_inverse = Vec::with_capacity(mesh.num_faces());
        let mut area = Vec::with_capacity(mesh.num_faces());
        for f in mesh.faces() {
            let (e1, e2) = (p[f[1]] - p[f[0]], p[f[2]] - p[f[0]]);
            // Orthonormal rest frame: u along e1, v in-plane, perpendicular.
            let u = e1.normalize();
            let n = e1.cross(&e2);
            let v = n.cross(&e1).normalize();
            let dm = Matrix2::new(e1.dot(&u), e2.dot(&u), e1.dot(&v), e2.dot(&v));
            rest_inverse.push(dm.try_inverse().ok_or(weft_mesh::Error::DegenerateFace {
                face: area.len(),
                area: 0.5 * n.norm(),
                tolerance: 0.0,
            })?);
            area.push(0.5 * n.norm());
        }
        let mu = young_2d / (2.0 * (1.0 + poisson));
        let lambda = young_2d * poisson / (1.0 - poisson * poisson);
        Ok(Self {
            faces: mesh.faces().to_vec(),
            rest_inverse,
            area,
            mu,
            lambda,
        })
    }

    /// Scales both Lamé parameters (Tan et al.'s 0.1·P_s variant).
    pub fn scale_stiffness(&mut self, factor: f64) {
        self.mu *= factor;
        self.lambda *= factor;
    }

    fn deformation_gradient(&self, t: usize, x: &[f64]) -> Matrix3x2<f64> {
        let f = self.faces[t];
        let x0 = vertex(x, f[0]);
        let ds = Matrix3x2::from_columns(&[vertex(x, f[1]) - x0, vertex(x, f[2]) - x0]);
        ds * self.rest_inverse[t]
    }

    /// Second Piola–Kirchhoff-like factor `S = 2μE + λ tr(E) I` and the strain.
    fn stress(&self, f: &Matrix3x2<f64>) -> (Matrix2<f64>, Matrix2<f64>) {
        let e = 0.5 * (f.transpose() * f - Matrix2::identity());
        (2.0 * self.mu * e + self.lambda * e.trace() * Matrix2::identity(), e)
    }

    fn local_gradient(&self, t: usize, x: &[f64]) -> SVector<f64, 9> {
        let f = self.deformation_gradient(t, x);
        let (s, _) = self.stress(&f);
        // ∂Ψ/∂D_s = P D_m⁻ᵀ with P = F S (first Piola–Kirchhoff).
        let g = self.area[t] * f * s * self.rest_inverse[t].transpose();
        let mut out = SVector::<f64, 9>::zeros();
        for k in 0..3 {
            out[3 + k] = g[(k, 0)];
            out[6 + k] = g[(k, 1)];
            out[k] = -g[(k, 0)] - g[(k, 1)];
        }
        out
    }

    fn local_hessian(&self, t: usize, x: &[f64]) -> SMatrix<f64, 9, 9> {
        let f = self.deformation_gradient(t, x);
        let (s, _) = self.stress(&f);
        let b = self.rest_inverse[t];
        let mut h = SMatrix::<f64, 9, 9>::zeros();
        // Column by column: perturb one DOF, differentiate P = F S analytically:
        // dP = dF S + F dS, dS = 2μ dE + λ tr(dE) I, dE = ½(dFᵀF + FᵀdF).
        for a in 0..3 {
            for k in 0..3 {
                let mut dds = Matrix3x2::zeros();
                match a {
                    0 => {
                        dds[(k, 0)] = -1.0;
                        dds[(k, 1)] = -1.0;
                    }
                    1 => dds[(k, 0)] = 1.0,
                    _ => dds[(k, 1)] = 1.0,
                }
                let df = dds * b;
                let de = 0.5 * (df.transpose() * f + f.transpose() * df);
                let ds = 2.0 * self.mu * de + self.lambda * de.trace() * Matrix2::identity();
                let dg = self.area[t] * (df * s + f * ds) * b.transpose();
                let col = 3 * a + k;
                for c in 0..3 {
                    h[(3 + c, col)] = dg[(c, 0)];
                    h[(6 + c, col)] = dg[(c, 1)];
                    h[(c, col)] = -dg[(c, 0)] - dg[(c, 1)];
                }
            }
        }
        h
    }
}

impl Energy for Membrane {
    fn name(&self) -> &'static str {
        "membrane"
    }
    fn hessian_pairs(&self, pairs: &mut Vec<(usize, usize)>) {
        for f in &self.faces {
            element_pairs(f, pairs);
        }
    }
    fn value(&self, x: &[f64]) -> f64 {
        (0..self.faces.len())
            .into_par_iter()
            .map(|t| {
                let f = self.deformation_gradient(t, x);
                let (_, e) = self.stress(&f);
                self.area[t] * (self.mu * e.norm_squared() + 0.5 * self.lambda * e.trace().powi(2))
            })
            .sum()
    }
    fn add_gradient(&self, x: &[f64], grad: &mut [f64]) {
        let locals: Vec<SVector<f64, 9>> = (0..self.faces.len())
            .into_par_iter()
            .map(|t| self.local_gradient(t, x))
            .collect();
        for (f, g) in self.faces.iter().zip(&locals) {
            scatter_gradient(f, g, grad);
        }
    }
    fn add_hessian(&self, x: &[f64], project: bool, hessian: &mut SymmetricMatrix) {
        let locals: Vec<SMatrix<f64, 9, 9>> = (0..self.faces.len())
            .into_par_iter()
            .map(|t| {
                let h = self.local_hessian(t, x);
                if project { project_psd(&h) } else { h }
            })
            .collect();
        for (f, h) in self.faces.iter().zip(&locals) {
            scatter_hessian(f, h, hessian);
        }
    }
}

/// Quadratic dihedral-angle bending (Grinspun et al. 2003 "Discrete Shells", as used by
/// Narain et al. 2012): per hinge `k_b · (θ − θ̄)² · ‖ē‖² / Ā` with `θ` the signed
/// dihedral angle, `ē` the rest edge and `Ā = (A₁ + A₂)/3` a third of the two rest
/// triangle areas. The weight makes the energy converge under refinement. `k_b` in N·m
/// (J). The gradient of `θ` is closed-form; its Hessian is exact, from forward-mode
/// differentiation of that gradient (see `dual`).
#[derive(Debug, Clone)]
pub struct DihedralBending {
    /// `[x0, x1, x2, x3]`: edge `x0 → x1`, opposite vertices `x2` (first face), `x3`.
    hinges: Vec<[usize; 4]>,
    rest_angle: Vec<f64>,
    weight: Vec<f64>,
    /// Squared rest length of each hinge edge: the scale of the degeneracy guard in
    /// [`angle_gradient`].
    rest_edge2: Vec<f64>,
    stiffness: f64,
}

impl DihedralBending {
    pub fn new(mesh: &TriMesh, topology: &Topology, stiffness: f64) -> Result<Self> {
        check_nonnegative("bending stiffness (N·m)", stiffness)?;
        mesh.check_face_areas(0.0)?;
        let p = mesh.positions();
        let areas = weft_mesh::geometry::face_areas(p, mesh.faces());
        let mut hinges = Vec::with_capacity(topology.hinges.len());
        let mut rest_angle = Vec::with_capacity(topology.hinges.len());
        let mut weight = Vec::with_capacity(topology.hinges.len());
        let mut rest_edge2 = Vec::with_capacity(topology.hinges.len());
        for h in &topology.hinges {
            let [x0, x1] = h.edge_vertices;
            let [x2, x3] = h.opposite;
            hinges.push([x0, x1, x2, x3]);
            rest_angle.push(weft_mesh::geometry::dihedral_angle(&p[x0], &p[x1], &p[x2], &p[x3]));
            let abar = (areas[h.faces[0]] + areas[h.faces[1]]) / 3.0;
            weight.push((p[x1] - p[x0]).norm_squared() / abar);
            rest_edge2.push((p[x1] - p[x0]).norm_squared());
        }
        Ok(Self {
            hinges,
            rest_angle,
            weight,
            rest_edge2,
            stiffness,
        })
    }

    pub fn scale_stiffness(&mut self, factor: f64) {
        self.stiffness *= factor;
    }

    fn angle(&self, h: usize, x: &[f64]) -> f64 {
        let [a, b, c, d] = self.hinges[h];
        weft_mesh::geometry::dihedral_angle(&vertex(x, a), &vertex(x, b), &vertex(x, c), &vertex(x, d))
    }

    /// Exact Hessian of θ in the hinge's 12 DOFs: the Jacobian of [`angle_gradient`],
    /// evaluated in forward mode.
    fn angle_hessian(&self, h: usize, x: &[f64]) -> SMatrix<f64, 12, 12> {
        let p: [V3<Dual<12>>; 4] = [0, 1, 2, 3].map(|k| {
            let v = vertex(x, self.hinges[h][k]);
            V3([0, 1, 2].map(|c| Dual::variable(v[c], 3 * k + c)))
        });
        let g = angle_gradient(&p, self.rest_edge2[h]);
        let mut out = SMatrix::<f64, 12, 12>::zeros();
        for (k, gk) in g.iter().enumerate() {
            for c in 0..3 {
                out.set_row(3 * k + c, &gk.0[c].d.transpose());
            }
        }
        // Symmetrise away round-off.
        0.5 * (out + out.transpose())
    }

    fn angle_gradient_f64(&self, h: usize, x: &[f64]) -> SVector<f64, 12> {
        let p: [V3<f64>; 4] = [0, 1, 2, 3].map(|k| {
            let v = vertex(x, self.hinges[h][k]);
            V3([v.x, v.y, v.z])
        });
        let g = angle_gradient(&p, self.rest_edge2[h]);
        SVector::<f64, 12>::from_fn(|i, _| g[i / 3].0[i % 3])
    }

    fn coefficient(&self, h: usize) -> f64 {
        self.stiffness * self.weight[h]
    }
}

/// Gradient of the signed dihedral angle θ of `weft_mesh::geometry::dihedral_angle`
/// with respect to `[x0, x1, x2, x3]` (Bridson, Marino & Fedkiw 2003 §4; Wardetzky et al.
/// 2007): with `e = x1 − x0`, face normals `n_A = e × (x2 − x0)`, `n_B = (x3 − x0) × e`,
/// `g_A = |e| n_A / |n_A|²` (unit normal over the height of x2), `t_A = (x2 − x0)·e/|e|²`
/// (and likewise for B):
/// `∂θ/∂x2 = −g_A`, `∂θ/∂x3 = −g_B`, `∂θ/∂x0 = (1 − t_A) g_A + (1 − t_B) g_B`,
/// `∂θ/∂x1 = t_A g_A + t_B g_B`.
///
/// A collapsed triangle (`n_A → 0`) or hinge edge (`e → 0`) makes these divisions 0/0,
/// while θ itself stays finite (0 there). The denominators are therefore floored by
/// `10⁻¹²` of their rest scale (`|ē|²` for `|e|²`, `|ē|⁴` for `|n|²`): below a
/// relative size of about 10⁻⁶ the gradient is bounded instead of NaN, and above it the
/// change is below 10⁻¹² relative — invisible to the finite-difference checks.
fn angle_gradient<T: Real>(p: &[V3<T>; 4], rest_edge2: f64) -> [V3<T>; 4] {
    let e = p[1].sub(&p[0]);
    let e2 = e.dot(&e) + T::cst(1e-12 * rest_edge2);
    let le = e2.sqrt();
    let na = e.cross(&p[2].sub(&p[0]));
    let nb = p[3].sub(&p[0]).cross(&e);
    let floor_n2 = T::cst(1e-12 * rest_edge2 * rest_edge2);
    let ga = na.scale(le / (na.dot(&na) + floor_n2));
    let gb = nb.scale(le / (nb.dot(&nb) + floor_n2));
    let ta = p[2].sub(&p[0]).dot(&e) / e2;
    let tb = p[3].sub(&p[0]).dot(&e) / e2;
    let one = T::cst(1.0);
    [
        ga.scale(one - ta).add(&gb.scale(one - tb)),
        ga.scale(ta).add(&gb.scale(tb)),
        ga.scale(-one),
        gb.scale(-one),
    ]
}

/// `θ − θ̄` wrapped into (−π, π] so a hinge folded through ±π does not jump.
fn angle_difference(theta: f64, rest: f64) -> f64 {
    let d = theta - rest;
    d - (2.0 * std::f64::consts::PI) * ((d + std::f64::consts::PI) / (2.0 * std::f64::consts::PI)).floor()
}

impl Energy for DihedralBending {
    fn name(&self) -> &'static str {
        "dihedral bending"
    }
    fn hessian_pairs(&self, pairs: &mut Vec<(usize, usize)>) {
        for h in &self.hinges {
            element_pairs(h, pairs);
        }
    }
    fn value(&self, x: &[f64]) -> f64 {
        (0..self.hinges.len())
            .into_par_iter()
            .map(|h| self.coefficient(h) * angle_difference(self.angle(h, x), self.rest_angle[h]).powi(2))
            .sum()
    }
    fn add_gradient(&self, x: &[f64], grad: &mut [f64]) {
        let locals: Vec<SVector<f64, 12>> = (0..self.hinges.len())
            .into_par_iter()
            .map(|h| {
                let d = angle_difference(self.angle(h, x), self.rest_angle[h]);
                self.angle_gradient_f64(h, x) * (2.0 * self.coefficient(h) * d)
            })
            .collect();
        for (hinge, g) in self.hinges.iter().zip(&locals) {
            scatter_gradient(hinge, g, grad);
        }
    }
    fn add_hessian(&self, x: &[f64], project: bool, hessian: &mut SymmetricMatrix) {
        let locals: Vec<SMatrix<f64, 12, 12>> = (0..self.hinges.len())
            .into_par_iter()
            .map(|h| {
                let g = self.angle_gradient_f64(h, x);
                let c = self.coefficient(h);
                let d = angle_difference(self.angle(h, x), self.rest_angle[h]);
                let gn = g * g.transpose() * (2.0 * c);
                let curvature = self.angle_hessian(h, x) * (2.0 * c * d);
                if project {
                    // The Gauss–Newton part is PSD; only the curvature term can make
                    // the block indefinite.
                    project_psd(&(gn + curvature))
                } else {
                    gn + curvature
                }
            })
            .collect();
        for (hinge, h) in self.hinges.iter().zip(&locals) {
            scatter_hessian(hinge, h, hessian);
        }
    }
}
