//! A primal–dual interior-point method for the inextensibility SOCP that solves only the
//! reduced `3V × 3V` normal equations.
//!
//! The problem, in the solver units of [`crate::socp`]:
//!
//! ```text
//! min_δ ½ δᵀ K δ   s.t.   s_e = b_e − A_e δ ∈ Q⁴,   A_e δ = [0; −D_e δ],   D_e = E_a − E_b
//! ```
//!
//! with `K = diag(w_v) ⊗ I₃`, optimality `Kδ + Aᵀz = 0`, `Aδ + s = b`, `s, z ∈ K`,
//! `sᵀz = 0` — the sign convention of Clarabel's `(x, s, z)`, so the polish and the
//! backward pass work on either solver's output.
//!
//! The method is the primal–dual path-following algorithm of CVXOPT's `coneqp`
//! (Vandenberghe, *The CVXOPT linear and quadratic cone program solvers*, 2010; function
//! `coneqp` in `cvxopt/src/python/coneprog.py`, NT scaling in `misc.compute_scaling`):
//! Nesterov–Todd scaling per cone, Mehrotra's predictor–corrector with full residuals
//! (`η = 0`), `coneqp`'s default infeasible starting point, and a step of `0.99` times
//! the exact step to the cones' boundary. The Newton system
//!
//! ```text
//! K dx + Aᵀ dz = bx,    A dx + ds = bz,    λ ∘ (W dz + W⁻¹ ds) = bs
//! ```
//!
//! is reduced by eliminating `ds` and `dz` cone by cone — `coneqp`'s KKT system
//! `[P Gᵀ; G −WᵀW]` with `P = K`, `G = A` and no equality constraints, `W` symmetric:
//! `dz = W⁻² (A dx − bz + W (λ ⋄ bs))`, leaving
//!
//! ```text
//! (K + Aᵀ W⁻² A) dx = bx + Aᵀ W⁻² (bz − W (λ ⋄ bs)).
//! ```
//!
//! Because the first row of `A_e` is zero, `Aᵀ W⁻² A = Σ_e D_eᵀ G_e D_e` with `G_e` the
//! lower-right `3 × 3` block of `W_e⁻²`: a matrix of `3 × 3` vertex blocks with exactly
//! the sparsity of the mesh edges, factorised by one sparse Cholesky whose symbolic
//! analysis is done once per mesh. Predictor and corrector share that factor. `G_e` is
//! `(I + 2 w̄₁ w̄₁ᵀ)/β²` (see [`NtScaling`]); `ds` is recovered from `A dx + ds = bz`.
//!
//! The solve stops when the relative primal residual `‖Aδ + s − b‖∞ / max(1, ‖b‖∞)`, the
//! relative dual residual `‖Kδ + Aᵀz‖∞ / max(1, ‖Kδ‖∞, ‖Aᵀz‖∞)` and the relative gap
//! `sᵀz / max(1, ½ δᵀKδ)` are all below the tolerance — or earlier, when the caller
//! certifies an optimum from an iterate (the polish, see [`ReducedIpm::solve`]). Too many
//! iterations, a non-finite residual, a point leaving the cones' interior or a vanishing
//! step is a typed [`Error::SolverFailed`], never a NaN.

use std::time::Instant;

use weft_linalg::{CholeskyFactor, dot};

use crate::error::{Error, Result};
use crate::kkt::{Block3, EdgeSystem};

/// Fraction of the exact step to the cones' boundary that is taken.
const STEP_FRACTION: f64 = 0.99;

/// Settings of one interior-point solve (a subset of `SocpSettings`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct IpmSettings {
    pub tolerance: f64,
    pub max_iterations: u32,
    /// Check each reduced solve's residual and refine it once if it is large.
    pub iterative_refinement: bool,
    pub verbose: bool,
    /// Relative gap and residuals below which `finish` is offered the iterate (once).
    pub early_finish_gap: f64,
    /// The tolerance to continue to if `finish` declines the point that meets `tolerance`
    /// (0: stop there).
    pub fallback_tolerance: f64,
}

/// An interior-point solution and what it took.
#[derive(Debug, Clone)]
pub(crate) struct IpmSolution {
    pub x: Vec<f64>,
    pub s: Vec<f64>,
    pub z: Vec<f64>,
    pub iterations: u32,
    /// `‖Aδ + s − b‖∞ / max(1, ‖b‖∞)`.
    pub primal_residual: f64,
    /// `‖Kδ + Aᵀz‖∞ / max(1, ‖Kδ‖∞, ‖Aᵀz‖∞)`.
    pub dual_residual: f64,
    /// The tolerance the point meets: `tolerance`, or the fallback it continued to.
    pub tolerance: f64,
    pub seconds: f64,
}

/// The reduced-system interior-point solver on one mesh's [`EdgeSystem`].
#[derive(Debug)]
pub(crate) struct ReducedIpm<'a> {
    system: &'a EdgeSystem,
}

impl<'a> ReducedIpm<'a> {
    pub fn new(system: &'a EdgeSystem) -> Self {
        Self { system }
    }

    /// `y += Aᵀ u` for cone vectors `u`: `(Aᵀu)_a −= u_e¹`, `(Aᵀu)_b += u_e¹`.
    fn add_transpose_product(&self, u: &[Cone], y: &mut [f64]) {
        for (&[a, b], ue) in self.system.edges().iter().zip(u) {
            for c in 0..3 {
                y[3 * a + c] -= ue[1 + c];
                y[3 * b + c] += ue[1 + c];
            }
        }
    }

    /// `A x` per cone: `A_e x = [0; −(x_a − x_b)]`.
    fn product(&self, x: &[f64]) -> Vec<Cone> {
        self.system
            .edges()
            .iter()
            .map(|&[a, b]| {
                let d = self.system.edge_difference(a, b, x);
                [0.0, -d[0], -d[1], -d[2]]
            })
            .collect()
    }

    /// Residuals at `(x, s, z)`: `r_x = Kx + Aᵀz`, `r_z = Ax + s − b`, and their norms.
    fn residuals(&self, b: &[Cone], x: &[f64], s: &[Cone], z: &[Cone]) -> Residuals {
        let w = self.system.weights();
        let kx: Vec<f64> = x.iter().enumerate().map(|(i, xi)| w[i / 3] * xi).collect();
        let mut at_z = vec![0.0; x.len()];
        self.add_transpose_product(z, &mut at_z);
        let rx: Vec<f64> = kx.iter().zip(&at_z).map(|(a, b)| a + b).collect();
        let mut rz = self.product(x);
        for ((r, se), be) in rz.iter_mut().zip(s).zip(b) {
            for k in 0..4 {
                r[k] += se[k] - be[k];
            }
        }
        let objective = 0.5 * dot(x, &kx);
        let dual_scale = max_abs(&kx).max(max_abs(&at_z)).max(1.0);
        Residuals {
            primal: max_abs(rz.as_flattened()) / max_abs(b.as_flattened()).max(1.0),
            dual: max_abs(&rx) / dual_scale,
            gap: dot(s.as_flattened(), z.as_flattened()),
            objective,
            rx,
            rz,
        }
    }

    /// Solves `(K + Σ_e D_eᵀ G_e D_e) y = rhs` in place. With `refine`, checks the
    /// residual (an edge-wise product, a tenth of a solve) and refines once if it is
    /// above `√ε` relative: the Cholesky solves measured 1e-15 to 1e-10 on the
    /// paper-size sheet, so refinement is a safeguard, not routine.
    fn solve_reduced(&self, blocks: &[Block3], factor: &CholeskyFactor, rhs: &mut [f64], refine: bool) {
        let b = refine.then(|| rhs.to_vec());
        factor.solve_in_place(rhs);
        if let Some(mut r) = b {
            let scale = max_abs(&r).max(f64::MIN_POSITIVE);
            let mut product = vec![0.0; rhs.len()];
            self.system.add_product(blocks, rhs, &mut product);
            r.iter_mut().zip(&product).for_each(|(r, p)| *r -= p);
            if max_abs(&r) > f64::EPSILON.sqrt() * scale {
                factor.solve_in_place(&mut r);
                rhs.iter_mut().zip(&r).for_each(|(x, d)| *x += d);
            }
        }
    }

    /// `coneqp`'s default starting point: `[K Aᵀ; A −I] [x; z] = [0; b]`, i.e. `x`
    /// minimises `½ xᵀKx + ½ ‖Ax − b‖²`, `s = b − Ax`, `z = Ax − b`; each of `s`, `z` is
    /// then shifted along the cones' identity `e = [1; 0]` by `1 + t`, `t` minus its
    /// smallest eigenvalue, unless `t < −10⁻⁸ max(‖·‖₂, 1)` (already well inside).
    fn initial_point(&self, b: &[Cone], refine: bool) -> Result<(Vec<f64>, Vec<Cone>, Vec<Cone>)> {
        let n = self.system.weights().len() * 3;
        let identity = vec![[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]; b.len()];
        let factor = self.system.factorize(&identity)?;
        let mut x = vec![0.0; n];
        self.add_transpose_product(b, &mut x);
        self.solve_reduced(&identity, &factor, &mut x, refine);
        let mut s = self.product(&x);
        for (se, be) in s.iter_mut().zip(b) {
            *se = std::array::from_fn(|k| be[k] - se[k]);
        }
        let mut z: Vec<Cone> = s.iter().map(|c| c.map(|v| -v)).collect();
        for v in [&mut s, &mut z] {
            // `max_e (‖v_e¹‖ − v_e⁰)`: minus the smallest eigenvalue over all cones.
            let t = v
                .iter()
                .map(|c| norm3(&c[1..4]) - c[0])
                .fold(f64::NEG_INFINITY, f64::max);
            let scale = dot(v.as_flattened(), v.as_flattened()).sqrt().max(1.0);
            if t >= -1e-8 * scale {
                v.iter_mut().for_each(|c| c[0] += 1.0 + t);
            }
        }
        Ok((x, s, z))
    }

    /// Solves the SOCP for the cone vector `b` (length `4m`, `b_e⁰ > 0`).
    ///
    /// `finish(x, s, z)` is offered the first iterate whose relative gap and residuals are
    /// below `settings.early_finish_gap`, and the iterate that meets the tolerance; if it
    /// returns a result (the caller has certified an optimum from that iterate), the solve
    /// stops there and returns it with the iterate. If it declines the converged iterate
    /// and `settings.fallback_tolerance` is tighter, the same iteration continues to that
    /// tolerance and offers its point too; should it fail on the way, the point that met
    /// `settings.tolerance` is returned (its [`IpmSolution::tolerance`] says which), with
    /// the iterations and seconds of the whole solve. The continuation is also given up
    /// once its primal residual and gap meet the tighter tolerance while the dual residual
    /// does not, for two iterations: on the paper-size sheet the dual residual then sits
    /// at a floor of 1e-10 to 1e-9 (the reduced solves' round-off as `z` concentrates on
    /// the active edges) until a point leaves the cones, 3–5 iterations later.
    pub fn solve<T>(
        &self,
        b: &[f64],
        settings: &IpmSettings,
        mut finish: impl FnMut(&[f64], &[f64], &[f64]) -> Option<T>,
    ) -> Result<(IpmSolution, Option<T>)> {
        let start = Instant::now();
        let b = b.as_chunks::<4>().0;
        let m = b.len();
        let (mut x, mut s, mut z) = self.initial_point(b, settings.iterative_refinement)?;
        let mut iterations = 0;
        let mut offered = false;
        let mut tolerance = settings.tolerance;
        let mut dual_stalled = 0;
        // The point that met `settings.tolerance`, kept while the solve continues.
        let mut met: Option<IpmSolution> = None;
        // Returns that point charged with the whole solve's iterations and time.
        let give_up = |mut point: IpmSolution, iterations: u32| {
            point.iterations = iterations;
            point.seconds = start.elapsed().as_secs_f64();
            point
        };
        // A solve that stops early returns the point that met the looser tolerance, if
        // there is one, and the error otherwise.
        let stop = |error: Error, iterations: u32, met: Option<IpmSolution>| match met {
            Some(point) => Ok((give_up(point, iterations), None)),
            None => Err(error),
        };
        let failed = |status: &str, iterations: u32| Error::SolverFailed {
            status: status.to_string(),
            iterations,
        };
        loop {
            let res = self.residuals(b, &x, &s, &z);
            let relative_gap = res.gap / res.objective.max(1.0);
            if settings.verbose {
                eprintln!(
                    "ipm {iterations:3}: pres {:.2e} dres {:.2e} gap {:.2e} obj {:.6e}",
                    res.primal, res.dual, relative_gap, res.objective
                );
            }
            if !(res.primal.is_finite() && res.dual.is_finite() && relative_gap.is_finite()) {
                return stop(failed("NumericalError", iterations), iterations, met);
            }
            let worst = res.primal.max(res.dual).max(relative_gap);
            let converged = worst <= tolerance;
            // The continuation is given up after two iterations in a row with the primal
            // residual and gap at the tighter tolerance and the dual residual above it.
            let stalled = met.is_some() && !converged && res.primal.max(relative_gap) <= tolerance;
            dual_stalled = if stalled { dual_stalled + 1 } else { 0 };
            if dual_stalled >= 2
                && let Some(point) = met.take()
            {
                return Ok((give_up(point, iterations), None));
            }
            let solution = |x: &[f64], s: &[Cone], z: &[Cone]| IpmSolution {
                x: x.to_vec(),
                s: s.as_flattened().to_vec(),
                z: z.as_flattened().to_vec(),
                iterations,
                primal_residual: res.primal,
                dual_residual: res.dual,
                tolerance,
                seconds: start.elapsed().as_secs_f64(),
            };
            if converged || (worst <= settings.early_finish_gap && !offered) {
                offered = true;
                if let Some(finished) = finish(&x, s.as_flattened(), z.as_flattened()) {
                    return Ok((solution(&x, &s, &z), Some(finished)));
                }
                if converged {
                    let tighter = settings.fallback_tolerance;
                    if !(tighter > 0.0 && tighter < tolerance) {
                        return Ok((solution(&x, &s, &z), None));
                    }
                    // Declined: continue from here rather than restart (a cold solve to
                    // the tighter tolerance cost as many iterations again).
                    met = Some(solution(&x, &s, &z));
                    tolerance = tighter;
                }
            }
            if iterations >= settings.max_iterations {
                return stop(failed("MaxIterations", iterations), iterations, met);
            }
            iterations += 1;
            if let Err(error) = self.advance(&res, m, settings, iterations, &mut x, &mut s, &mut z) {
                return stop(error, iterations, met);
            }
        }
    }

    /// Iteration `iteration` of the predictor–corrector method from `(x, s, z)` with
    /// residuals `res`, in place.
    #[allow(clippy::too_many_arguments)]
    fn advance(
        &self,
        res: &Residuals,
        m: usize,
        settings: &IpmSettings,
        iteration: u32,
        x: &mut [f64],
        s: &mut [Cone],
        z: &mut [Cone],
    ) -> Result<()> {
        let failed = |status: &str| Error::SolverFailed {
            status: status.to_string(),
            iterations: iteration,
        };
        let scalings: Vec<NtScaling> = s
            .iter()
            .zip(z.iter())
            .map(|(se, ze)| NtScaling::new(se, ze))
            .collect::<Option<_>>()
            .ok_or_else(|| failed("NumericalError"))?;
        let blocks: Vec<Block3> = scalings.iter().map(NtScaling::inverse_squared_block).collect();
        let factor_start = Instant::now();
        let factor = self.system.factorize(&blocks)?;
        let factor_seconds = factor_start.elapsed().as_secs_f64();
        let newton = NewtonSystem {
            ipm: self,
            blocks: &blocks,
            factor: &factor,
            scalings: &scalings,
            refine: settings.iterative_refinement,
        };
        let bx: Vec<f64> = res.rx.iter().map(|v| -v).collect();
        let bz: Vec<Cone> = res.rz.iter().map(|c| c.map(|v| -v)).collect();

        // Predictor (affine scaling): λ ∘ (W dz + W⁻¹ ds) = −λ ∘ λ.
        let lambda_sq: Vec<Cone> = scalings.iter().map(|w| jordan_product(&w.lambda, &w.lambda)).collect();
        let mut bs: Vec<Cone> = lambda_sq.iter().map(|l| l.map(|v| -v)).collect();
        let affine = newton.solve(&bx, &bz, &bs);
        let alpha_affine = max_step(&scalings, s, z, &affine).min(1.0);
        // Mehrotra's centring σ = (1 − α_aff)³, Clarabel's rule (`centering_parameter`
        // in its `solver/core/solver.rs`). CVXOPT's `(gap_aff / gap)³` took the same
        // 14 iterations on the paper-size sheet.
        let sigma = (1.0 - alpha_affine).powi(3);
        let mu = res.gap / m as f64;

        // Corrector: −λ∘λ − (W⁻¹ds_aff) ∘ (W dz_aff) + σμ e.
        for (((bse, l2), ds), dz) in bs
            .iter_mut()
            .zip(&lambda_sq)
            .zip(&affine.ds_scaled)
            .zip(&affine.dz_scaled)
        {
            let second_order = jordan_product(ds, dz);
            *bse = std::array::from_fn(|k| -l2[k] - second_order[k]);
            bse[0] += sigma * mu;
        }
        let step = newton.solve(&bx, &bz, &bs);
        let alpha = (STEP_FRACTION * max_step(&scalings, s, z, &step)).min(1.0);
        if settings.verbose {
            eprintln!(
                "      α_aff {alpha_affine:.3} σ {sigma:.2e} α {alpha:.3} (assembly + factorisation {:.1} ms)",
                1e3 * factor_seconds
            );
        }
        if !(alpha > 1e-12) {
            return Err(failed("StepTooSmall"));
        }
        x.iter_mut().zip(&step.dx).for_each(|(v, d)| *v += alpha * d);
        for (v, d) in s.iter_mut().zip(&step.ds).chain(z.iter_mut().zip(&step.dz)) {
            for k in 0..4 {
                v[k] += alpha * d[k];
            }
        }
        Ok(())
    }
}

/// One `Q⁴` cone's part of a cone vector.
type Cone = [f64; 4];

/// The largest `α` with `s + α ds` and `z + α dz` in every cone (`s`, `z` the point the
/// scalings were computed at, whose `sᵀJs`, `zᵀJz` they keep).
fn max_step(scalings: &[NtScaling], s: &[Cone], z: &[Cone], step: &NewtonStep) -> f64 {
    let mut alpha = f64::INFINITY;
    for (((w, (se, ze)), ds), dz) in scalings.iter().zip(s.iter().zip(z)).zip(&step.ds).zip(&step.dz) {
        alpha = alpha
            .min(max_cone_step(se, w.s_jnorm_sq, ds))
            .min(max_cone_step(ze, w.z_jnorm_sq, dz));
    }
    alpha
}

struct Residuals {
    primal: f64,
    dual: f64,
    gap: f64,
    objective: f64,
    rx: Vec<f64>,
    rz: Vec<Cone>,
}

/// A Newton direction, with the scaled `W⁻¹ ds`, `W dz` Mehrotra's correction needs.
struct NewtonStep {
    dx: Vec<f64>,
    ds: Vec<Cone>,
    dz: Vec<Cone>,
    ds_scaled: Vec<Cone>,
    dz_scaled: Vec<Cone>,
}

/// One iteration's factorised Newton system.
struct NewtonSystem<'a> {
    ipm: &'a ReducedIpm<'a>,
    blocks: &'a [Block3],
    factor: &'a CholeskyFactor,
    scalings: &'a [NtScaling],
    refine: bool,
}

impl NewtonSystem<'_> {
    /// Solves `K dx + Aᵀ dz = bx`, `A dx + ds = bz`, `λ ∘ (W dz + W⁻¹ ds) = bs` through the
    /// reduced system (see the module doc).
    fn solve(&self, bx: &[f64], bz: &[Cone], bs: &[Cone]) -> NewtonStep {
        // t = λ ⋄ bs (so W dz + W⁻¹ ds = t) and y = W⁻²(bz − W t).
        let y: Vec<Cone> = self
            .scalings
            .iter()
            .zip(bz.iter().zip(bs))
            .map(|(w, (bze, bse))| {
                let wt = w.apply(&jordan_divide(&w.lambda, bse));
                w.apply_inverse_squared(&std::array::from_fn(|k| bze[k] - wt[k]))
            })
            .collect();
        let mut dx = bx.to_vec();
        self.ipm.add_transpose_product(&y, &mut dx);
        self.ipm.solve_reduced(self.blocks, self.factor, &mut dx, self.refine);
        let m = self.scalings.len();
        let mut step = NewtonStep {
            dx,
            ds: Vec::with_capacity(m),
            dz: Vec::with_capacity(m),
            ds_scaled: Vec::with_capacity(m),
            dz_scaled: Vec::with_capacity(m),
        };
        let adx = self.ipm.product(&step.dx);
        for (((w, adx), ye), bze) in self.scalings.iter().zip(&adx).zip(&y).zip(bz) {
            // dz = W⁻² A dx − y. ds from the linear equation A dx + ds = bz rather than
            // from W dz + W⁻¹ ds = t: near the solution W² has eigenvalues of very
            // different sizes and W (t − W dz) cancels, which let the primal residual
            // grow again in the last iterations.
            let h_adx = w.apply_inverse_squared(adx);
            let dz: Cone = std::array::from_fn(|k| h_adx[k] - ye[k]);
            let ds: Cone = std::array::from_fn(|k| bze[k] - adx[k]);
            step.dz_scaled.push(w.apply(&dz));
            step.ds_scaled.push(w.apply_inverse(&ds));
            step.dz.push(dz);
            step.ds.push(ds);
        }
        step
    }
}

/// The Nesterov–Todd scaling of one `Q⁴` cone, as CVXOPT's `misc.compute_scaling`:
/// `W = β (2 v vᵀ − J)`, `J = diag(1, −1, −1, −1)`, `vᵀ J v = 1`, with `W z = W⁻¹ s = λ`.
/// `W² = β² (2 w̄ w̄ᵀ − J)` maps `z` to `s`; `v` is its hyperbolic square root.
#[derive(Debug, Clone, Copy)]
struct NtScaling {
    /// `sᵀJs` and `zᵀJz` of the point the scaling was computed at.
    s_jnorm_sq: f64,
    z_jnorm_sq: f64,
    beta: f64,
    /// `w̄ = (s̄ + J z̄) / (2γ)`, `s̄ = s / √(sᵀJs)`, `z̄ = z / √(zᵀJz)`, `γ = √((1 + s̄ᵀz̄)/2)`.
    w: [f64; 4],
    /// `v = (w̄ + e) / √(2 (w̄₀ + 1))`.
    v: [f64; 4],
    lambda: [f64; 4],
}

impl NtScaling {
    /// `None` unless `s` and `z` are strictly inside the cone.
    fn new(s: &Cone, z: &Cone) -> Option<Self> {
        let (s_jnorm_sq, z_jnorm_sq) = (cone_norm_sq(s)?, cone_norm_sq(z)?);
        let (s_norm, z_norm) = (s_jnorm_sq.sqrt(), z_jnorm_sq.sqrt());
        let sb: [f64; 4] = std::array::from_fn(|k| s[k] / s_norm);
        let zb: [f64; 4] = std::array::from_fn(|k| z[k] / z_norm);
        let gamma = ((1.0 + dot(&sb, &zb)) / 2.0).sqrt();
        let w = [
            (sb[0] + zb[0]) / (2.0 * gamma),
            (sb[1] - zb[1]) / (2.0 * gamma),
            (sb[2] - zb[2]) / (2.0 * gamma),
            (sb[3] - zb[3]) / (2.0 * gamma),
        ];
        let root = (2.0 * (w[0] + 1.0)).sqrt();
        let v = [(w[0] + 1.0) / root, w[1] / root, w[2] / root, w[3] / root];
        // λ = W z without forming W (as `compute_scaling`): λ̄₀ = γ,
        // λ̄₁ = ((γ + z̄₀) s̄₁ + (γ + s̄₀) z̄₁) / (s̄₀ + z̄₀ + 2γ), λ = √(‖s‖_J ‖z‖_J) λ̄.
        let scale = (s_norm * z_norm).sqrt();
        let denom = sb[0] + zb[0] + 2.0 * gamma;
        let mut lambda = [scale * gamma, 0.0, 0.0, 0.0];
        for k in 1..4 {
            lambda[k] = scale * ((gamma + zb[0]) * sb[k] + (gamma + sb[0]) * zb[k]) / denom;
        }
        let beta = (s_norm / z_norm).sqrt();
        let ok = beta.is_finite() && root.is_finite() && lambda.iter().all(|x| x.is_finite());
        ok.then_some(Self {
            s_jnorm_sq,
            z_jnorm_sq,
            beta,
            w,
            v,
            lambda,
        })
    }

    /// `W u = β (2 v (vᵀu) − J u)`.
    fn apply(&self, u: &[f64; 4]) -> [f64; 4] {
        let vu = dot(&self.v, u);
        let ju = [u[0], -u[1], -u[2], -u[3]];
        std::array::from_fn(|k| self.beta * (2.0 * self.v[k] * vu - ju[k]))
    }

    /// `W⁻¹ u = (2 J v (vᵀ J u) − J u) / β`.
    fn apply_inverse(&self, u: &[f64; 4]) -> [f64; 4] {
        let ju = [u[0], -u[1], -u[2], -u[3]];
        let jv = [self.v[0], -self.v[1], -self.v[2], -self.v[3]];
        let vju = dot(&self.v, &ju);
        std::array::from_fn(|k| (2.0 * jv[k] * vju - ju[k]) / self.beta)
    }

    /// `W⁻² u = (2 J w̄ (w̄ᵀ J u) − J u) / β²`, the inverse of `W² = β² (2 w̄ w̄ᵀ − J)`.
    fn apply_inverse_squared(&self, u: &[f64; 4]) -> [f64; 4] {
        let ju = [u[0], -u[1], -u[2], -u[3]];
        let jw = [self.w[0], -self.w[1], -self.w[2], -self.w[3]];
        let wju = dot(&self.w, &ju);
        let inv_b2 = 1.0 / (self.beta * self.beta);
        std::array::from_fn(|k| inv_b2 * (2.0 * jw[k] * wju - ju[k]))
    }

    /// `G`, the lower-right `3 × 3` block of `W⁻²`: `(I + 2 w̄₁ w̄₁ᵀ) / β²`.
    fn inverse_squared_block(&self) -> Block3 {
        let inv_b2 = 1.0 / (self.beta * self.beta);
        std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                let id = if i == j { 1.0 } else { 0.0 };
                inv_b2 * (id + 2.0 * self.w[i + 1] * self.w[j + 1])
            })
        })
    }
}

/// `vᵀJv = v₀² − ‖v₁‖²`, or `None` if `v` is not strictly inside `Q⁴`.
fn cone_norm_sq(v: &Cone) -> Option<f64> {
    let n1 = norm3(&v[1..4]);
    // (v₀ − ‖v₁‖)(v₀ + ‖v₁‖) avoids the cancellation of v₀² − ‖v₁‖² near the boundary.
    let q = (v[0] - n1) * (v[0] + n1);
    (v[0] > n1 && q > 0.0).then_some(q)
}

/// The Jordan product of `Q⁴`: `u ∘ v = [uᵀv; u₀ v₁ + v₀ u₁]`.
fn jordan_product(u: &[f64; 4], v: &[f64; 4]) -> [f64; 4] {
    [
        dot(u, v),
        u[0] * v[1] + v[0] * u[1],
        u[0] * v[2] + v[0] * u[2],
        u[0] * v[3] + v[0] * u[3],
    ]
}

/// `λ ⋄ v`: the `x` with `λ ∘ x = v`, for `λ` inside the cone:
/// `x₀ = (λ₀ v₀ − λ₁ᵀv₁) / (λᵀJλ)`, `x₁ = (v₁ − x₀ λ₁) / λ₀`.
fn jordan_divide(lambda: &[f64; 4], v: &[f64; 4]) -> [f64; 4] {
    let l1n = norm3(&lambda[1..4]);
    let rho = (lambda[0] - l1n) * (lambda[0] + l1n);
    let l1v1 = lambda[1] * v[1] + lambda[2] * v[2] + lambda[3] * v[3];
    let x0 = (lambda[0] * v[0] - l1v1) / rho;
    [
        x0,
        (v[1] - x0 * lambda[1]) / lambda[0],
        (v[2] - x0 * lambda[2]) / lambda[0],
        (v[3] - x0 * lambda[3]) / lambda[0],
    ]
}

/// The largest `α ≥ 0` with `x + α d ∈ Q⁴` (`∞` if the ray stays inside), for `x`
/// inside with `xᵀJx = c > 0`: the smallest positive root of
/// `q(α) = (x + αd)ᵀ J (x + αd) = aα² + 2bα + c`, in cancellation-free form. (`c` comes
/// accurately from the NT scaling; a rounding error in `a` only moves the root by a
/// relative `ε`.)
fn max_cone_step(x: &Cone, c: f64, d: &Cone) -> f64 {
    let b = x[0] * d[0] - (x[1] * d[1] + x[2] * d[2] + x[3] * d[3]);
    let a = d[0] * d[0] - (d[1] * d[1] + d[2] * d[2] + d[3] * d[3]);
    let disc = b * b - a * c;
    if b < 0.0 {
        // Both roots positive (a > 0), one (a < 0), or the linear root (a = 0).
        if disc >= 0.0 {
            c / (-b + disc.sqrt())
        } else {
            f64::INFINITY
        }
    } else if a < 0.0 {
        (b + disc.sqrt()) / -a
    } else {
        f64::INFINITY
    }
}

fn norm3(v: &[f64]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Max-norm, `+∞` if any entry is not finite (weft-linalg's, on a slice).
fn max_abs(v: &[f64]) -> f64 {
    weft_linalg::max_abs(v.iter().copied())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_interior(seed: &mut u64) -> [f64; 4] {
        let mut next = || {
            *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let v1 = [next(), next(), next()];
        [norm3(&v1) + 0.01 + next().abs(), v1[0], v1[1], v1[2]]
    }

    #[test]
    fn nt_scaling_maps_z_and_s_to_the_same_point() {
        let mut seed = 7;
        for _ in 0..20 {
            let (s, z) = (random_interior(&mut seed), random_interior(&mut seed));
            let w = NtScaling::new(&s, &z).unwrap();
            let (wz, winv_s) = (w.apply(&z), w.apply_inverse(&s));
            for k in 0..4 {
                assert!(
                    (wz[k] - w.lambda[k]).abs() < 1e-12 * w.lambda[0],
                    "{wz:?} vs {:?}",
                    w.lambda
                );
                assert!((winv_s[k] - w.lambda[k]).abs() < 1e-12 * w.lambda[0]);
            }
            // W⁻¹ inverts W, and the closed-form block is that of W⁻².
            let v = random_interior(&mut seed);
            let back = w.apply_inverse(&w.apply(&v));
            assert!((0..4).all(|k| (back[k] - v[k]).abs() < 1e-12 * v[0]));
            let g = w.inverse_squared_block();
            for j in 0..4 {
                let mut unit = [0.0; 4];
                unit[j] = 1.0;
                let col = w.apply_inverse(&w.apply_inverse(&unit));
                let direct = w.apply_inverse_squared(&unit);
                for i in 0..4 {
                    assert!((col[i] - direct[i]).abs() < 1e-10 * direct[j].abs().max(1.0));
                    if i > 0 && j > 0 {
                        assert!((col[i] - g[i - 1][j - 1]).abs() < 1e-10 * direct[j].abs().max(1.0));
                    }
                }
            }
        }
    }

    /// The reduced solve must satisfy the full Newton system it eliminates:
    /// `K dx + Aᵀ dz = bx`, `A dx + ds = bz`, `λ ∘ (W dz + W⁻¹ ds) = bs`.
    #[test]
    fn reduced_newton_solve_satisfies_the_full_system() {
        let mut seed = 17;
        // Two triangles sharing an edge, plus a dangling edge: 5 vertices, 6 edges.
        let edges = [[0, 1], [1, 2], [2, 0], [1, 3], [3, 2], [3, 4]];
        let weights = [0.7, 1.3, 1.0, 0.9, 1.1];
        let system = EdgeSystem::new(5, &edges, &weights).unwrap();
        let ipm = ReducedIpm::new(&system);
        let m = edges.len();
        let cones = |seed: &mut u64, count: usize| -> Vec<Cone> { (0..count).map(|_| random_interior(seed)).collect() };
        let (s, z) = (cones(&mut seed, m), cones(&mut seed, m));
        let scalings: Vec<NtScaling> = s
            .iter()
            .zip(&z)
            .map(|(se, ze)| NtScaling::new(se, ze).unwrap())
            .collect();
        let blocks: Vec<Block3> = scalings.iter().map(NtScaling::inverse_squared_block).collect();
        let factor = system.factorize(&blocks).unwrap();
        let newton = NewtonSystem {
            ipm: &ipm,
            blocks: &blocks,
            factor: &factor,
            scalings: &scalings,
            refine: false,
        };
        let bx: Vec<f64> = cones(&mut seed, 4).as_flattened()[..15].to_vec();
        let (bz, bs) = (cones(&mut seed, m), cones(&mut seed, m));
        let step = newton.solve(&bx, &bz, &bs);
        let mut rx: Vec<f64> = (0..15).map(|i| weights[i / 3] * step.dx[i] - bx[i]).collect();
        ipm.add_transpose_product(&step.dz, &mut rx);
        assert!(max_abs(&rx) < 1e-12, "dual equation {rx:?}");
        let adx = ipm.product(&step.dx);
        for (e, w) in scalings.iter().enumerate() {
            let (ds, dz) = (step.ds[e], step.dz[e]);
            let wdz = w.apply(&dz);
            let winv_ds = w.apply_inverse(&ds);
            let sum: Cone = std::array::from_fn(|k| wdz[k] + winv_ds[k]);
            let comp = jordan_product(&w.lambda, &sum);
            for k in 0..4 {
                assert!(
                    (adx[e][k] + ds[k] - bz[e][k]).abs() < 1e-12,
                    "primal equation, cone {e}"
                );
                assert!((comp[k] - bs[e][k]).abs() < 1e-10, "complementarity, cone {e}");
                assert!((wdz[k] - step.dz_scaled[e][k]).abs() < 1e-12);
                assert!((winv_ds[k] - step.ds_scaled[e][k]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn jordan_divide_inverts_the_product() {
        let mut seed = 11;
        let (l, v) = (random_interior(&mut seed), random_interior(&mut seed));
        let x = jordan_divide(&l, &v);
        let back = jordan_product(&l, &x);
        assert!((0..4).all(|k| (back[k] - v[k]).abs() < 1e-12));
    }

    #[test]
    fn max_cone_step_lands_on_the_boundary() {
        let mut seed = 13;
        for _ in 0..50 {
            let x = random_interior(&mut seed);
            let d = random_interior(&mut seed).map(|v| 3.0 * v - 1.0);
            let alpha = max_cone_step(&x, cone_norm_sq(&x).unwrap(), &d);
            if alpha.is_finite() {
                let y: [f64; 4] = std::array::from_fn(|k| x[k] + alpha * d[k]);
                assert!((y[0] - norm3(&y[1..4])).abs() < 1e-10 * (1.0 + alpha), "{y:?}");
                assert!(y[0] >= -1e-12);
            } else {
                let y: [f64; 4] = std::array::from_fn(|k| x[k] + 1e6 * d[k]);
                assert!(y[0] >= norm3(&y[1..4]));
            }
        }
    }
}
