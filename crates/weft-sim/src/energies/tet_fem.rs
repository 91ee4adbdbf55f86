//! Hyperelastic tetrahedral FEM: linear (Cauchy strain), co-rotational linear, St.
//! Venant–Kirchhoff and Neo-Hookean materials on linear tetrahedra (NNWarp Eq. 1, 3, 8).
//!
//! Per element the deformation gradient is `F = D_s D_m⁻¹` (Sifakis & Barbič 2012, FEM
//! course notes §4.2), the energy is `V_rest Ψ(F)`, the nodal gradient is `V_rest P(F)
//! D_m⁻ᵀ` (P the first Piola–Kirchhoff stress) and the `12 × 12` Hessian is
//! `V_rest Gᵀ (∂P/∂F) G` with `G = ∂vec(F)/∂x` (ibid. §4.3–4.4). `∂P/∂F` is analytic for
//! every material. The SPD projection (Teran et al. 2005) is applied to the `9 × 9`
//! `∂P/∂F` rather than the `12 × 12` element block: `Gᵀ A G` is PSD whenever `A` is, and
//! the smaller eigenproblem is about three times cheaper.
//!
//! Lamé parameters from Young's modulus `E` (Pa) and Poisson ratio `ν`:
//! `μ = E / (2(1 + ν))`, `λ = E ν / ((1 + ν)(1 − 2ν))` (any elasticity text, e.g.
//! Sifakis & Barbič §3.1), with `E > 0` and `0 ≤ ν < ½` enforced.
//!
//! **Inverted elements.** Linear, co-rotational and StVK energies are finite for every
//! `F`, including `det F ≤ 0` (co-rotational uses the rotation-variant SVD of Irving et
//! al. 2004, which keeps `det R = +1` and gives the smallest singular value the sign of
//! `det F`). Neo-Hookean's `ln J` is undefined for `J = det F ≤ 0`, so below
//! `J₀ =` [`NEO_HOOKEAN_J_MIN`] it is replaced by its second-order Taylor expansion about
//! `J₀` — the energy-level analogue of the constitutive extrapolation of Irving, Teran &
//! Fedkiw 2004 and of Stomakhin et al. 2012 ("Energetically consistent invertible
//! elasticity"). The extended energy is C², finite for all `F`, and still pushes an
//! inverted element back towards `J > 0` (`∂Ψ/∂J < 0` for `J < J₀`), so Newton un-inverts
//! it; above `J₀` it is exactly NNWarp Eq. 8.

#![allow(non_snake_case)]

use std::sync::{Arc, Mutex};

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rayon::prelude::*;
use weft_linalg::{SymmetricMatrix, SymmetricPattern};
use weft_mesh::TetMesh;

use crate::energy::{Energy, element_pairs, vertex};
use crate::error::{Error, Result};

/// `J₀` below which Neo-Hookean's `ln J` is replaced by its quadratic Taylor expansion.
pub const NEO_HOOKEAN_J_MIN: f64 = 0.1;

/// Lamé parameters `μ` (shear modulus) and `λ`, both in Pa.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LameParameters {
    pub mu: f64,
    pub lambda: f64,
}

impl LameParameters {
    /// From Young's modulus `young` (Pa, > 0) and Poisson ratio `poisson` (`0 ≤ ν < ½`):
    /// `μ = E/(2(1+ν))`, `λ = Eν/((1+ν)(1−2ν))`.
    pub fn from_young_poisson(young: f64, poisson: f64) -> Result<Self> {
        if !(young.is_finite() && young > 0.0) {
            return Err(Error::InvalidParameter {
                name: "Young's modulus",
                value: young,
                reason: "must be positive and finite (Pa)",
            });
        }
        if !(poisson.is_finite() && (0.0..0.5).contains(&poisson)) {
            return Err(Error::InvalidParameter {
                name: "Poisson ratio",
                value: poisson,
                reason: "must lie in [0, 0.5) (0.5 is incompressible and makes λ infinite)",
            });
        }
        let mu = young / (2.0 * (1.0 + poisson));
        let lambda = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
        Ok(Self { mu, lambda })
    }

    /// Young's modulus `E = μ(3λ + 2μ)/(λ + μ)` (Pa).
    pub fn young(&self) -> f64 {
        self.mu * (3.0 * self.lambda + 2.0 * self.mu) / (self.lambda + self.mu)
    }

    /// Poisson ratio `ν = λ / (2(λ + μ))`.
    pub fn poisson(&self) -> f64 {
        self.lambda / (2.0 * (self.lambda + self.mu))
    }
}

/// An isotropic hyperelastic material law `Ψ(F)` (J/m³).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Material {
    /// `Ψ = μ ε:ε + λ/2 tr²ε`, `ε = ½(F + Fᵀ) − I` (NNWarp Eq. 1). Not rotation invariant.
    Linear,
    /// `Ψ = μ ‖F − R‖² + λ/2 tr²(RᵀF − I)`, `F = RS` the polar decomposition
    /// (McAdams et al. 2011; NNWarp's "co-rotation").
    CoRotational,
    /// `Ψ = μ E:E + λ/2 tr²E`, `E = ½(FᵀF − I)` the Green strain (NNWarp Eq. 3).
    #[serde(rename = "stvk")]
    StVK,
    /// `Ψ = μ/2 (I₁ − ln I₃ − 3) + λ/8 ln²I₃` (NNWarp Eq. 8), i.e.
    /// `μ/2 (‖F‖² − 3) − μ ln J + λ/2 ln²J`, with `ln J` extended below
    /// [`NEO_HOOKEAN_J_MIN`] (see the module docs).
    NeoHookean,
}

impl Material {
    pub const ALL: [Material; 4] = [
        Material::Linear,
        Material::CoRotational,
        Material::StVK,
        Material::NeoHookean,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Material::Linear => "linear elasticity",
            Material::CoRotational => "co-rotational elasticity",
            Material::StVK => "StVK elasticity",
            Material::NeoHookean => "Neo-Hookean elasticity",
        }
    }

    /// Energy density `Ψ(F)` (J/m³).
    pub fn energy_density(self, lame: &LameParameters, F: &Matrix3<f64>) -> f64 {
        self.energy_density_of_displacement_gradient(lame, &(F - Matrix3::identity()))
    }

    /// `Ψ(I + G)` evaluated from the displacement gradient `G = F − I` without the
    /// cancellations of `‖F‖² − 3` and `ln det F` near the rest state: their round-off
    /// (of order `μ ε_machine` per unit volume) would otherwise swamp the energy changes
    /// Newton's line search compares when the strain is small and the material stiff.
    pub fn energy_density_of_displacement_gradient(self, lame: &LameParameters, G: &Matrix3<f64>) -> f64 {
        let (mu, lambda) = (lame.mu, lame.lambda);
        match self {
            Material::Linear => {
                let eps = 0.5 * (G + G.transpose());
                mu * eps.norm_squared() + 0.5 * lambda * eps.trace().powi(2)
            }
            Material::CoRotational => {
                let s = signed_singular_values(&(G + Matrix3::identity()));
                let tr = s.sum() - 3.0;
                mu * (s - Vector3::repeat(1.0)).norm_squared() + 0.5 * lambda * tr * tr
            }
            Material::StVK => {
                let E = 0.5 * (G + G.transpose() + G.transpose() * G);
                mu * E.norm_squared() + 0.5 * lambda * E.trace().powi(2)
            }
            Material::NeoHookean => {
                // det(I + G) − 1 = tr G + ½(tr²G − tr G²) + det G; ‖F‖² − 3 = 2 tr G + ‖G‖².
                let tr = G.trace();
                let j_minus_1 = tr + 0.5 * (tr * tr - (G * G).trace()) + G.determinant();
                let l = extended_log_1p(j_minus_1);
                0.5 * mu * (2.0 * tr + G.norm_squared()) - mu * l + 0.5 * lambda * l * l
            }
        }
    }

    /// First Piola–Kirchhoff stress `P = ∂Ψ/∂F` (Pa).
    pub fn stress(self, lame: &LameParameters, F: &Matrix3<f64>) -> Matrix3<f64> {
        let (mu, lambda) = (lame.mu, lame.lambda);
        let I = Matrix3::identity();
        match self {
            Material::Linear => {
                let eps = 0.5 * (F + F.transpose()) - I;
                2.0 * mu * eps + lambda * eps.trace() * I
            }
            Material::CoRotational => {
                let svd = RotationVariantSvd::new(F);
                let R = svd.rotation();
                2.0 * mu * (F - R) + lambda * (svd.sigma.sum() - 3.0) * R
            }
            Material::StVK => {
                let E = 0.5 * (F.transpose() * F - I);
                F * (2.0 * mu * E + lambda * E.trace() * I)
            }
            Material::NeoHookean => {
                let (l, dl, _) = extended_log(F.determinant());
                mu * F + (lambda * l - mu) * dl * cofactor(F)
            }
        }
    }

    /// `∂P/∂F` as a `9 × 9` matrix over column-major `vec(F)` (entry `F_ij` at `3j + i`).
    pub fn stress_derivative(self, lame: &LameParameters, F: &Matrix3<f64>) -> SMatrix<f64, 9, 9> {
        let (mu, lambda) = (lame.mu, lame.lambda);
        let I = Matrix3::identity();
        let mut A = SMatrix::<f64, 9, 9>::zeros();
        let mut put =
            |k: usize, dP: Matrix3<f64>| A.set_column(k, &SVector::<f64, 9>::from_column_slice(dP.as_slice()));
        match self {
            Material::Linear => {
                for k in 0..9 {
                    let dF = basis(k);
                    put(k, mu * (dF + dF.transpose()) + lambda * dF.trace() * I);
                }
            }
            Material::CoRotational => {
                // dP = 2μ dF + (λ(tr S − 3) − 2μ) dR + λ (R : dF) R, using d tr S = R : dF.
                // dR = U Ω Vᵀ with Ω_ij = (M_ij − M_ji)/(σ_i + σ_j), M = Uᵀ dF V — the
                // twist modes of Kim & Eberle 2022 ("Dynamic deformables", §5.4).
                let svd = RotationVariantSvd::new(F);
                let R = svd.rotation();
                let c = lambda * (svd.sigma.sum() - 3.0) - 2.0 * mu;
                for k in 0..9 {
                    let dF = basis(k);
                    put(
                        k,
                        2.0 * mu * dF + c * svd.rotation_differential(&dF) + lambda * R.dot(&dF) * R,
                    );
                }
            }
            Material::StVK => {
                let E = 0.5 * (F.transpose() * F - I);
                let S = 2.0 * mu * E + lambda * E.trace() * I;
                for k in 0..9 {
                    let dF = basis(k);
                    let dE = 0.5 * (dF.transpose() * F + F.transpose() * dF);
                    put(k, dF * S + F * (2.0 * mu * dE + lambda * dE.trace() * I));
                }
            }
            Material::NeoHookean => {
                // P = μF + (λL − μ) L' C with C = cof F = ∂J/∂F, so
                // dP = μ dF + ((λL − μ) L'' + λ L'²)(C : dF) C + (λL − μ) L' dC[dF].
                let (l, dl, ddl) = extended_log(F.determinant());
                let C = cofactor(F);
                let a = (lambda * l - mu) * ddl + lambda * dl * dl;
                let b = (lambda * l - mu) * dl;
                for k in 0..9 {
                    let dF = basis(k);
                    put(k, mu * dF + a * C.dot(&dF) * C + b * cofactor_differential(F, &dF));
                }
            }
        }
        A
    }
}

fn basis(k: usize) -> Matrix3<f64> {
    let mut m = Matrix3::zeros();
    m[(k % 3, k / 3)] = 1.0;
    m
}

/// `(L(J), L'(J), L''(J))`: `ln J` for `J ≥ J₀`, its quadratic Taylor expansion about
/// `J₀` below.
fn extended_log(J: f64) -> (f64, f64, f64) {
    const J0: f64 = NEO_HOOKEAN_J_MIN;
    if J >= J0 {
        (J.ln(), 1.0 / J, -1.0 / (J * J))
    } else {
        let d = J - J0;
        (
            J0.ln() + d / J0 - d * d / (2.0 * J0 * J0),
            1.0 / J0 - d / (J0 * J0),
            -1.0 / (J0 * J0),
        )
    }
}

/// `L(1 + d)` of [`extended_log`], accurate for small `d = J − 1`.
fn extended_log_1p(d: f64) -> f64 {
    if 1.0 + d >= NEO_HOOKEAN_J_MIN {
        d.ln_1p()
    } else {
        extended_log(1.0 + d).0
    }
}

/// `cof F = ∂ det F / ∂F`: columns `f₁×f₂, f₂×f₀, f₀×f₁` of `F = [f₀ f₁ f₂]`.
fn cofactor(F: &Matrix3<f64>) -> Matrix3<f64> {
    let (f0, f1, f2) = (F.column(0), F.column(1), F.column(2));
    Matrix3::from_columns(&[f1.cross(&f2), f2.cross(&f0), f0.cross(&f1)])
}

/// The differential of [`cofactor`] in direction `dF`.
fn cofactor_differential(F: &Matrix3<f64>, dF: &Matrix3<f64>) -> Matrix3<f64> {
    let (f0, f1, f2) = (F.column(0), F.column(1), F.column(2));
    let (d0, d1, d2) = (dF.column(0), dF.column(1), dF.column(2));
    Matrix3::from_columns(&[
        d1.cross(&f2) + f1.cross(&d2),
        d2.cross(&f0) + f2.cross(&d0),
        d0.cross(&f1) + f0.cross(&d1),
    ])
}

/// `F = U diag(σ) Vᵀ` with `det U = det V = +1`; the smallest singular value carries the
/// sign of `det F` (Irving, Teran & Fedkiw 2004, §5).
struct RotationVariantSvd {
    u: Matrix3<f64>,
    sigma: Vector3<f64>,
    v: Matrix3<f64>,
}

impl RotationVariantSvd {
    fn new(F: &Matrix3<f64>) -> Self {
        let svd = F.svd_unordered(true, true);
        let mut u = svd.u.unwrap_or_else(Matrix3::identity);
        let mut v = svd.v_t.map_or_else(Matrix3::identity, |vt| vt.transpose());
        let mut sigma = svd.singular_values;
        let k = sigma.imin();
        if u.determinant() < 0.0 {
            u.column_mut(k).neg_mut();
            sigma[k] = -sigma[k];
        }
        if v.determinant() < 0.0 {
            v.column_mut(k).neg_mut();
            sigma[k] = -sigma[k];
        }
        Self { u, sigma, v }
    }

    fn rotation(&self) -> Matrix3<f64> {
        self.u * self.v.transpose()
    }

    /// `dR` for the polar rotation `R = U Vᵀ`. Where `σ_i + σ_j` vanishes (an element
    /// flattened to a line or inverted) the polar rotation is not differentiable; the
    /// denominator is clamped to [`TWIST_DENOMINATOR_REL`] times the largest `|σ|`,
    /// which bounds the twist stiffness instead of producing an infinite or NaN Hessian.
    /// The clamp is relative so that a uniformly shrunken element (all `σ` small but
    /// equal, where `dR` is perfectly well defined) is not clamped.
    fn rotation_differential(&self, dF: &Matrix3<f64>) -> Matrix3<f64> {
        let M = self.u.transpose() * dF * self.v;
        let mut omega = Matrix3::zeros();
        let floor = (TWIST_DENOMINATOR_REL * self.sigma.amax()).max(f64::MIN_POSITIVE);
        for (i, j) in [(0, 1), (0, 2), (1, 2)] {
            let w = (M[(i, j)] - M[(j, i)]) / (self.sigma[i] + self.sigma[j]).max(floor);
            omega[(i, j)] = w;
            omega[(j, i)] = -w;
        }
        self.u * omega * self.v.transpose()
    }
}

/// Lower bound on `σ_i + σ_j` in the co-rotational rotation differential, relative to
/// the largest `|σ|`.
const TWIST_DENOMINATOR_REL: f64 = 1e-6;

/// Singular values of `F` with the smallest one signed by `det F`.
fn signed_singular_values(F: &Matrix3<f64>) -> Vector3<f64> {
    let mut s = F.svd_unordered(false, false).singular_values;
    if F.determinant() < 0.0 {
        let k = s.imin();
        s[k] = -s[k];
    }
    s
}

/// Elements processed per parallel batch (bounds the scratch memory to a few MB).
const BATCH: usize = 4096;

/// The elastic energy `Σ_e V_e Ψ(F_e)` of a tetrahedral mesh.
#[derive(Debug)]
pub struct TetElasticity {
    material: Material,
    lame: LameParameters,
    tets: Vec<[usize; 4]>,
    rest: Vec<Vector3<f64>>,
    /// Rows `b_a` of the `4 × 3` gradient operator: `F = Σ_a x_a b_aᵀ`.
    shape_gradients: Vec<[Vector3<f64>; 4]>,
    volumes: Vec<f64>,
    parallel: bool,
    slots: Mutex<Option<SlotTable>>,
}

/// Storage slots of every element's `12 × 12` block in one matrix pattern.
#[derive(Debug)]
struct SlotTable {
    pattern: Arc<SymmetricPattern>,
    /// 144 per element, row-major over local DOFs; `u32::MAX` for lower-triangle entries.
    slots: Vec<u32>,
}

impl TetElasticity {
    /// The elastic energy of `mesh` (rest shape = its positions) for `material`.
    pub fn new(mesh: &TetMesh, material: Material, lame: LameParameters) -> Result<Self> {
        Self::from_rest(mesh.positions(), mesh.tets(), material, lame)
    }

    /// As [`TetElasticity::new`] from raw rest positions (m) and tets; fails on a
    /// degenerate or inverted rest element or bad Lamé parameters.
    pub fn from_rest(
        rest: &[Vector3<f64>],
        tets: &[[usize; 4]],
        material: Material,
        lame: LameParameters,
    ) -> Result<Self> {
        if !(lame.mu.is_finite() && lame.mu > 0.0) {
            return Err(Error::InvalidParameter {
                name: "Lamé μ",
                value: lame.mu,
                reason: "must be positive and finite",
            });
        }
        if !(lame.lambda.is_finite() && lame.lambda >= 0.0) {
            return Err(Error::InvalidParameter {
                name: "Lamé λ",
                value: lame.lambda,
                reason: "must be non-negative and finite",
            });
        }
        if let Some(&v) = tets.iter().flatten().find(|&&v| v >= rest.len()) {
            return Err(Error::VertexOutOfRange {
                what: "tetrahedron",
                index: v,
                num_vertices: rest.len(),
            });
        }
        let inverses = weft_mesh::geometry::tet_rest_inverses(rest, tets)?;
        let volumes = weft_mesh::geometry::tet_volumes(rest, tets);
        let shape_gradients = inverses
            .iter()
            .map(|dm_inv| {
                let b1 = dm_inv.row(0).transpose();
                let b2 = dm_inv.row(1).transpose();
                let b3 = dm_inv.row(2).transpose();
                [-(b1 + b2 + b3), b1, b2, b3]
            })
            .collect();
        Ok(Self {
            material,
            lame,
            tets: tets.to_vec(),
            rest: rest.to_vec(),
            shape_gradients,
            volumes,
            parallel: true,
            slots: Mutex::new(None),
        })
    }

    pub fn material(&self) -> Material {
        self.material
    }
    pub fn lame(&self) -> LameParameters {
        self.lame
    }
    pub fn tets(&self) -> &[[usize; 4]] {
        &self.tets
    }
    /// Rest volumes (m³).
    pub fn rest_volumes(&self) -> &[f64] {
        &self.volumes
    }
    /// Evaluate elements with rayon (default) or serially; results are bit-identical.
    pub fn set_parallel(&mut self, parallel: bool) {
        self.parallel = parallel;
    }

    /// Deformation gradient of element `e` at positions `x`.
    pub fn deformation_gradient(&self, x: &[f64], e: usize) -> Matrix3<f64> {
        self.displacement_gradient(x, e) + Matrix3::identity()
    }

    /// Displacement gradient `G = F − I = Σ_a (x_a − x̄_a) b_aᵀ` of element `e`, formed
    /// from displacements so that it keeps full relative precision at small strain.
    pub fn displacement_gradient(&self, x: &[f64], e: usize) -> Matrix3<f64> {
        let mut G = Matrix3::zeros();
        for (&v, b) in self.tets[e].iter().zip(&self.shape_gradients[e]) {
            G += (vertex(x, v) - self.rest[v]) * b.transpose();
        }
        G
    }

    /// Per-element energies (J) at `x`.
    pub fn element_energies(&self, x: &[f64]) -> Vec<f64> {
        let f = |e: usize| {
            self.volumes[e]
                * self
                    .material
                    .energy_density_of_displacement_gradient(&self.lame, &self.displacement_gradient(x, e))
        };
        if self.parallel {
            (0..self.tets.len()).into_par_iter().map(f).collect()
        } else {
            (0..self.tets.len()).map(f).collect()
        }
    }

    fn element_gradient(&self, x: &[f64], e: usize) -> SVector<f64, 12> {
        let P = self.material.stress(&self.lame, &self.deformation_gradient(x, e));
        let mut g = SVector::<f64, 12>::zeros();
        for (a, b) in self.shape_gradients[e].iter().enumerate() {
            let f = self.volumes[e] * P * b;
            g.fixed_rows_mut::<3>(3 * a).copy_from(&f);
        }
        g
    }

    /// The `12 × 12` Hessian block of element `e` (optionally PSD-projected).
    pub fn element_hessian(&self, x: &[f64], e: usize, project: bool) -> SMatrix<f64, 12, 12> {
        let F = self.deformation_gradient(x, e);
        let mut A = self.material.stress_derivative(&self.lame, &F);
        if project && self.material != Material::Linear {
            // Linear elasticity's ∂P/∂F is constant and PSD for μ > 0, λ ≥ 0.
            A = crate::energy::project_psd(&A);
        }
        // G maps the 12 nodal DOFs to vec(F): ∂F_ij/∂x_{a,i} = b_a[j].
        let mut G = SMatrix::<f64, 9, 12>::zeros();
        for (a, b) in self.shape_gradients[e].iter().enumerate() {
            for j in 0..3 {
                for i in 0..3 {
                    G[(3 * j + i, 3 * a + i)] = b[j];
                }
            }
        }
        self.volumes[e] * G.transpose() * A * G
    }

    fn map_batches<T: Send>(&self, f: impl Fn(usize) -> T + Sync + Send, mut consume: impl FnMut(usize, T)) {
        let n = self.tets.len();
        let mut buffer: Vec<T> = Vec::with_capacity(BATCH.min(n));
        for start in (0..n).step_by(BATCH) {
            let end = (start + BATCH).min(n);
            buffer.clear();
            if self.parallel {
                (start..end).into_par_iter().map(&f).collect_into_vec(&mut buffer);
            } else {
                buffer.extend((start..end).map(&f));
            }
            for (k, item) in buffer.drain(..).enumerate() {
                consume(start + k, item);
            }
        }
    }

    fn slot_table(&self, pattern: &Arc<SymmetricPattern>) -> std::sync::MutexGuard<'_, Option<SlotTable>> {
        let mut guard = self.slots.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let stale = guard.as_ref().is_none_or(|t| !Arc::ptr_eq(&t.pattern, pattern));
        if stale {
            assert!(
                pattern.nnz() < u32::MAX as usize,
                "matrix pattern too large for 32-bit slots"
            );
            let mut slots = Vec::with_capacity(144 * self.tets.len());
            for t in &self.tets {
                for p in 0..12 {
                    for q in 0..12 {
                        let (r, c) = (3 * t[p / 3] + p % 3, 3 * t[q / 3] + q % 3);
                        let slot = if r <= c {
                            pattern.slot(r, c).unwrap_or_else(|| {
                                panic!(
                                    "entry ({r}, {c}) of a tet block is not in the pattern: hessian_pairs was not used"
                                )
                            }) as u32
                        } else {
                            u32::MAX
                        };
                        slots.push(slot);
                    }
                }
            }
            *guard = Some(SlotTable {
                pattern: pattern.clone(),
                slots,
            });
        }
        guard
    }
}

impl Energy for TetElasticity {
    fn name(&self) -> &'static str {
        self.material.name()
    }
    fn hessian_pairs(&self, pairs: &mut Vec<(usize, usize)>) {
        for t in &self.tets {
            element_pairs(t, pairs);
        }
    }
    fn value(&self, x: &[f64]) -> f64 {
        // Summed serially in element order so the result does not depend on threads.
        self.element_energies(x).iter().sum()
    }
    fn add_gradient(&self, x: &[f64], grad: &mut [f64]) {
        self.map_batches(
            |e| self.element_gradient(x, e),
            |e, g| {
                for (a, &v) in self.tets[e].iter().enumerate() {
                    for k in 0..3 {
                        grad[3 * v + k] += g[3 * a + k];
                    }
                }
            },
        );
    }
    fn add_hessian(&self, x: &[f64], project: bool, hessian: &mut SymmetricMatrix) {
        let pattern = hessian.pattern().clone();
        let table = self.slot_table(&pattern);
        let slots = &table.as_ref().expect("slot table was just built").slots;
        let values = hessian.values_mut();
        self.map_batches(
            |e| self.element_hessian(x, e, project),
            |e, h| {
                let s = &slots[144 * e..144 * (e + 1)];
                for p in 0..12 {
                    for q in 0..12 {
                        let slot = s[12 * p + q];
                        if slot != u32::MAX {
                            values[slot as usize] += h[(p, q)];
                        }
                    }
                }
            },
        );
    }
}
