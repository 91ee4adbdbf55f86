//! The physics as candle custom ops: ACAP⁻¹ (Tan et al. §IV-A, Eq. 6) and L_phys (Eq. 4)
//! with hand-written backward passes that call weft-acap's vector–Jacobian product and
//! weft-sim's gradient. Nothing of either is reimplemented in tensors; each op converts
//! f32 ↔ f64 at its boundary (through [`crate::convert`]) and runs the f64 code, in
//! parallel over the batch.

use std::sync::Arc;

use candle_core::{CpuStorage, CustomOp1, CustomOp3, Layout, Shape, Tensor};
use nalgebra::Vector3;
use rayon::prelude::*;
use weft_acap::{Feature, FeatureNormalization, PoissonPseudoInverse};
use weft_sim::ImplicitEuler;

use crate::convert;

fn op_error(e: impl std::fmt::Display) -> candle_core::Error {
    candle_core::Error::Msg(e.to_string())
}

/// The contiguous f32 slice of a storage, or an error naming the op.
fn f32_slice<'a>(op: &str, s: &'a CpuStorage, l: &Layout) -> candle_core::Result<&'a [f32]> {
    let all = s
        .as_slice::<f32>()
        .map_err(|_| op_error(format!("{op}: expects f32 input")))?;
    match l.contiguous_offsets() {
        Some((a, b)) => Ok(&all[a..b]),
        None => Err(op_error(format!("{op}: expects a contiguous input"))),
    }
}

/// Channels of an ACAP feature (`weft_acap::Feature`): what [`AcapInverse`] takes per
/// vertex and what the mesh autoencoder reconstructs. Here, below both the autoencoder and
/// its fused kernels, so that each imports it downward.
pub const FEATURE_CHANNELS: usize = 9;

/// ACAP⁻¹ ∘ denormalisation on a batch: `[B, V, 9]` normalised features → `[B, V, 3]`
/// positions (metres), each frame with its own pinned (grasped) vertex positions.
#[derive(Debug, Clone)]
pub struct AcapInverse {
    inverse: Arc<PoissonPseudoInverse>,
    normalization: FeatureNormalization,
    pins: Arc<Vec<Vec<Vector3<f64>>>>,
}

impl AcapInverse {
    /// `pins[b]` are frame `b`'s positions of `inverse`'s pinned vertices.
    pub fn new(
        inverse: Arc<PoissonPseudoInverse>,
        normalization: FeatureNormalization,
        pins: Vec<Vec<Vector3<f64>>>,
    ) -> Self {
        Self {
            inverse,
            normalization,
            pins: Arc::new(pins),
        }
    }

    /// Applies the op to `features` (`[B, V, 9]`, f32, normalised).
    pub fn apply(&self, features: &Tensor) -> crate::Result<Tensor> {
        let (b, v, c) = features.dims3()?;
        if c != 9 || v != self.inverse.num_vertices() || b != self.pins.len() {
            return Err(crate::Error::Shape {
                what: "ACAP⁻¹ input",
                expected: format!("[{}, {}, 9]", self.pins.len(), self.inverse.num_vertices()),
                got: format!("{:?}", features.dims()),
            });
        }
        Ok(features.contiguous()?.apply_op1(self.clone())?)
    }

    fn frames(&self, x: &[f32], v: usize) -> candle_core::Result<Vec<Vec<Feature>>> {
        let x = convert::f32_to_f64("ACAP⁻¹ input features", x).map_err(op_error)?;
        Ok(x.chunks_exact(9 * v)
            .map(|frame| {
                frame
                    .chunks_exact(9)
                    .map(|f| self.normalization.denormalize(&std::array::from_fn(|d| f[d])))
                    .collect()
            })
            .collect())
    }
}

impl CustomOp1 for AcapInverse {
    fn name(&self) -> &'static str {
        "acap-inverse"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let (b, v, _) = l.shape().dims3()?;
        let frames = self.frames(f32_slice(self.name(), s, l)?, v)?;
        let decoded: Vec<Vec<Vector3<f64>>> = frames
            .par_iter()
            .zip(self.pins.par_iter())
            .map(|(f, pins)| self.inverse.decode(f, pins))
            .collect::<Result<_, _>>()
            .map_err(op_error)?;
        let flat: Vec<f64> = decoded.iter().flatten().flat_map(|p| [p.x, p.y, p.z]).collect();
        let out = convert::f64_to_f32("ACAP⁻¹ positions", &flat).map_err(op_error)?;
        Ok((CpuStorage::F32(out), Shape::from((b, v, 3))))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let (b, v, _) = arg.dims3()?;
        let x: Vec<f32> = arg.flatten_all()?.to_vec1()?;
        let frames = self.frames(&x, v)?;
        let g: Vec<f32> = grad_res.flatten_all()?.to_vec1()?;
        let g = convert::f32_to_points("ACAP⁻¹ output gradient", &g).map_err(op_error)?;
        let scale = self.normalization.scale();
        let grads: Vec<Vec<Feature>> = frames
            .par_iter()
            .zip(g.par_chunks(v))
            .map(|(f, gp)| self.inverse.vjp(f, gp).map(|d| d.features))
            .collect::<Result<_, _>>()
            .map_err(op_error)?;
        // Chain through the denormalisation: ∂f/∂n = scale, per dimension.
        let flat: Vec<f64> = grads
            .iter()
            .flatten()
            .flat_map(|gf| (0..9).map(move |d| gf[d] * scale[d]))
            .collect();
        let out = convert::f64_to_f32("ACAP⁻¹ feature gradient", &flat).map_err(op_error)?;
        Ok(Some(Tensor::from_vec(out, (b, v, 9), arg.device())?))
    }
}

/// Tan et al.'s `L_phys(p_{m−2}, p_{m−1}, p_m, q_m)` (Eq. 4) per frame of a batch, from
/// three `[B, V, 3]` position tensors (metres) to `[B]` (joules). The grasped DOFs of
/// `p_m` carry `q_m`.
///
/// The backward pass returns ∂L_phys/∂p_m and **no gradient for p_{m−2} and p_{m−1}**:
/// Tan et al. stop them (Eq. 9–10), so that training drives each frame to its own
/// minimiser instead of the minimiser of the summed losses.
#[derive(Debug, Clone)]
pub struct LPhys {
    integrator: Arc<ImplicitEuler>,
}

impl LPhys {
    /// `integrator` supplies the masses, Δt, the potential terms and the grasp mask.
    pub fn new(integrator: Arc<ImplicitEuler>) -> Self {
        Self { integrator }
    }

    pub fn apply(&self, prev2: &Tensor, prev1: &Tensor, p: &Tensor) -> crate::Result<Tensor> {
        let n = self.integrator.positions().len();
        for (what, t) in [("p_{m-2}", prev2), ("p_{m-1}", prev1), ("p_m", p)] {
            let (_, v, c) = t.dims3()?;
            if 3 * v != n || c != 3 || t.dims() != p.dims() {
                return Err(crate::Error::Shape {
                    what,
                    expected: format!("[B, {}, 3], the same for all three", n / 3),
                    got: format!("{:?}", t.dims()),
                });
            }
        }
        // Eq. 9–10: the previous frames enter as constants. Detaching them (rather than
        // only returning no gradient for them) also keeps candle from expecting one for
        // the network nodes that produced them.
        Ok(prev2
            .detach()
            .contiguous()?
            .apply_op3(&prev1.detach().contiguous()?, &p.contiguous()?, self.clone())?)
    }

    fn split(&self, what: &'static str, x: &[f32]) -> candle_core::Result<Vec<Vec<f64>>> {
        let n = self.integrator.positions().len();
        let x = convert::f32_to_f64(what, x).map_err(op_error)?;
        Ok(x.chunks_exact(n).map(<[f64]>::to_vec).collect())
    }
}

impl CustomOp3 for LPhys {
    fn name(&self) -> &'static str {
        "l-phys"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let b = l3.shape().dims3()?.0;
        let prev2 = self.split("p_{m-2}", f32_slice(self.name(), s1, l1)?)?;
        let prev1 = self.split("p_{m-1}", f32_slice(self.name(), s2, l2)?)?;
        let p = self.split("p_m", f32_slice(self.name(), s3, l3)?)?;
        let values: Vec<f64> = (0..b)
            .into_par_iter()
            .map(|k| self.integrator.l_phys(&prev2[k], &prev1[k], &p[k]))
            .collect::<Result<_, _>>()
            .map_err(op_error)?;
        let out = convert::f64_to_f32("L_phys", &values).map_err(op_error)?;
        Ok((CpuStorage::F32(out), Shape::from(b)))
    }

    fn bwd(
        &self,
        arg1: &Tensor,
        arg2: &Tensor,
        arg3: &Tensor,
        _res: &Tensor,
        grad_res: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let prev2 = self.split("p_{m-2}", &arg1.flatten_all()?.to_vec1()?)?;
        let prev1 = self.split("p_{m-1}", &arg2.flatten_all()?.to_vec1()?)?;
        let p = self.split("p_m", &arg3.flatten_all()?.to_vec1()?)?;
        let scale: Vec<f32> = grad_res.to_vec1()?;
        let n = self.integrator.positions().len();
        let grads: Vec<Vec<f64>> = (0..p.len())
            .into_par_iter()
            .map(|k| {
                let mut g = vec![0.0; n];
                self.integrator
                    .l_phys_gradient(&prev2[k], &prev1[k], &p[k], &mut g)
                    .map(|_| g.iter().map(|x| x * scale[k] as f64).collect())
            })
            .collect::<Result<_, _>>()
            .map_err(op_error)?;
        let flat: Vec<f64> = grads.into_iter().flatten().collect();
        let out = convert::f64_to_f32("∂L_phys/∂p_m", &flat).map_err(op_error)?;
        // Eq. 9–10: no gradient flows into p_{m−2} or p_{m−1}.
        Ok((None, None, Some(Tensor::from_vec(out, arg3.dims(), arg3.device())?)))
    }
}

/// The cloth's elastic potential `P_s + P_b` (Tan et al. Eq. 3) on a batch: `[B, V, 3]`
/// positions (metres) → `[B]` energies (J), with its gradient from weft-sim's terms. Cloth
/// inverse kinematics minimises it through `ACAP⁻¹ ∘ D` (§V-A).
#[derive(Debug, Clone)]
pub struct ClothPotential {
    integrator: Arc<ImplicitEuler>,
}

impl ClothPotential {
    /// The potential of `integrator`'s elastic terms ([`weft_sim::is_cloth_elastic`]).
    pub fn new(integrator: Arc<ImplicitEuler>) -> Self {
        Self { integrator }
    }

    fn terms(&self) -> impl Iterator<Item = &dyn weft_sim::Energy> {
        self.integrator
            .terms()
            .iter()
            .map(|t| t.as_ref())
            .filter(|t| weft_sim::is_cloth_elastic(*t))
    }

    pub fn apply(&self, p: &Tensor) -> crate::Result<Tensor> {
        let n = self.integrator.positions().len();
        let (_, v, c) = p.dims3()?;
        if 3 * v != n || c != 3 {
            return Err(crate::Error::Shape {
                what: "cloth potential input",
                expected: format!("[B, {}, 3]", n / 3),
                got: format!("{:?}", p.dims()),
            });
        }
        Ok(p.contiguous()?.apply_op1(self.clone())?)
    }

    fn split(&self, x: &[f32]) -> candle_core::Result<Vec<Vec<f64>>> {
        let n = self.integrator.positions().len();
        let x = convert::f32_to_f64("cloth potential input", x).map_err(op_error)?;
        Ok(x.chunks_exact(n).map(<[f64]>::to_vec).collect())
    }
}

impl CustomOp1 for ClothPotential {
    fn name(&self) -> &'static str {
        "cloth-potential"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let p = self.split(f32_slice(self.name(), s, l)?)?;
        let values: Vec<f64> = p.par_iter().map(|x| self.terms().map(|t| t.value(x)).sum()).collect();
        let out = convert::f64_to_f32("cloth potential", &values).map_err(op_error)?;
        Ok((CpuStorage::F32(out), Shape::from(p.len())))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad_res: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let p = self.split(&arg.flatten_all()?.to_vec1()?)?;
        let scale: Vec<f32> = grad_res.to_vec1()?;
        let flat: Vec<f64> = p
            .par_iter()
            .zip(&scale)
            .flat_map_iter(|(x, &s)| {
                let mut g = vec![0.0; x.len()];
                for t in self.terms() {
                    t.add_gradient(x, &mut g);
                }
                g.into_iter().map(move |v| v * s as f64)
            })
            .collect();
        let out = convert::f64_to_f32("∂(P_s + P_b)/∂p", &flat).map_err(op_error)?;
        Ok(Some(Tensor::from_vec(out, arg.dims(), arg.device())?))
    }
}

/// A flat batch of `[B, V, 3]` values as its `B` examples of `3V` each.
fn examples(flat: &[f64], num_vertices: usize) -> Vec<&[f64]> {
    flat.chunks_exact(3 * num_vertices).collect()
}

/// The solutions of an op's last forward pass, kept for its backward pass: keyed by the
/// exact inputs, so the backward pass of that same call reuses them and any other call
/// solves again (the forward solve is deterministic either way).
#[derive(Debug)]
struct LastForward<S> {
    inputs: Vec<f32>,
    solutions: Vec<S>,
}

type ForwardCache<S> = Arc<std::sync::Mutex<Option<LastForward<S>>>>;

/// The cached solutions for exactly `inputs`, if the last forward pass had them.
fn take_cached<S>(cache: &ForwardCache<S>, inputs: &[f32]) -> Option<Vec<S>> {
    let mut guard = cache.lock().ok()?;
    if guard.as_ref().is_some_and(|l| l.inputs == inputs) {
        guard.take().map(|l| l.solutions)
    } else {
        None
    }
}

fn store_cached<S>(cache: &ForwardCache<S>, inputs: Vec<f32>, solutions: Vec<S>) {
    if let Ok(mut guard) = cache.lock() {
        *guard = Some(LastForward { inputs, solutions });
    }
}

/// `keys` as the op's example keys, one per batch entry of `predictions`.
fn example_keys(what: &'static str, predictions: &Tensor, keys: &[usize]) -> crate::error::Result<Arc<Vec<usize>>> {
    if keys.len() != predictions.dim(0)? {
        return Err(crate::error::Error::Shape {
            what,
            expected: format!("one per example ({})", predictions.dim(0)?),
            got: format!("{}", keys.len()),
        });
    }
    Ok(Arc::new(keys.to_vec()))
}

/// Geng et al.'s quasistatic projection (§5) as a candle op over a batch: predictions
/// `[B, V, 3]` (f32, metres) and the zero-length scaling μ — `[1]` for one global μ or `[V]`
/// for one μ_i per vertex (Eq. 15–16) — to the equilibria `r*` `[B, V, 3]`. The solves run
/// in f64 in weft-proj, one example per thread.
///
/// The backward pass is weft-proj's adjoint (Eq. 14 for `r̂`, Eq. 16 for μ, summed over the
/// batch). It reuses the forward pass's solutions when it follows it with the same inputs
/// (the op keeps the last call's), and solves again otherwise.
///
/// Warm starts (training): [`QuasistaticProjection::apply_keyed`] names each example of the
/// batch, and Newton starts from that example's previous equilibrium instead of from its
/// prediction.
#[derive(Debug, Clone)]
pub struct QuasistaticProjection {
    layer: Arc<weft_proj::QuasistaticLayer>,
    keys: Option<Arc<Vec<usize>>>,
    previous: Arc<weft_proj::WarmStarts<usize, Vec<f64>>>,
    last: ForwardCache<weft_proj::quasistatic::QuasistaticSolution>,
}

impl QuasistaticProjection {
    pub fn new(layer: Arc<weft_proj::QuasistaticLayer>) -> Self {
        Self {
            layer,
            keys: None,
            previous: Arc::default(),
            last: Arc::default(),
        }
    }

    /// `r*` for predictions `[B, V, 3]` and μ (`[1]` or `[V]`), differentiable in both.
    pub fn apply(&self, predictions: &Tensor, mu: &Tensor) -> crate::error::Result<Tensor> {
        self.check(predictions, mu)?;
        let op = Self {
            keys: None,
            ..self.clone()
        };
        Ok(predictions.contiguous()?.apply_op2(&mu.contiguous()?, op)?)
    }

    /// [`apply`](Self::apply) with example `keys[b]` for batch entry `b`: each solve starts
    /// from the equilibrium this op last found for the same key (a warm start), and its
    /// result is remembered for the key's next call.
    pub fn apply_keyed(&self, predictions: &Tensor, mu: &Tensor, keys: &[usize]) -> crate::error::Result<Tensor> {
        self.check(predictions, mu)?;
        let op = Self {
            keys: Some(example_keys("quasistatic projection keys", predictions, keys)?),
            ..self.clone()
        };
        Ok(predictions.contiguous()?.apply_op2(&mu.contiguous()?, op)?)
    }

    fn check(&self, predictions: &Tensor, mu: &Tensor) -> crate::error::Result<()> {
        let v = self.layer.num_vertices();
        let (_, pv, three) = predictions.dims3()?;
        let m = mu.dims1()?;
        if pv != v || three != 3 || !(m == 1 || m == v) {
            return Err(crate::error::Error::Shape {
                what: "quasistatic projection input",
                expected: format!("predictions [B, {v}, 3] and mu [1] or [{v}]"),
                got: format!("{:?} and {:?}", predictions.dims(), mu.dims()),
            });
        }
        Ok(())
    }

    fn scaling(mu: &[f32]) -> weft_proj::ZeroLengthScaling {
        if mu.len() == 1 {
            weft_proj::ZeroLengthScaling::Global(f64::from(mu[0]))
        } else {
            weft_proj::ZeroLengthScaling::PerVertex(mu.iter().map(|&m| f64::from(m)).collect())
        }
    }

    /// Every example's forward solve, in parallel, warm-started where a key has a previous
    /// equilibrium.
    fn solve(
        &self,
        predictions: &[f32],
        mu: &[f32],
    ) -> candle_core::Result<Vec<weft_proj::quasistatic::QuasistaticSolution>> {
        let x = convert::f32_to_f64("quasistatic projection input", predictions).map_err(op_error)?;
        let preds = examples(&x, self.layer.num_vertices());
        let starts = self
            .previous
            .starts(self.keys.as_deref().map(Vec::as_slice), preds.len());
        let scaling = Self::scaling(mu);
        let solutions: Vec<_> = self
            .layer
            .forward_batch_from(&preds, &scaling, &starts)
            .into_iter()
            .map(|r| r.map(|(solution, _)| solution).map_err(op_error))
            .collect::<candle_core::Result<_>>()?;
        self.previous.remember(
            self.keys.as_deref().map(Vec::as_slice),
            solutions.iter().map(|s| s.positions().to_vec()),
        );
        Ok(solutions)
    }

    fn inputs(predictions: &[f32], mu: &[f32]) -> Vec<f32> {
        predictions.iter().chain(mu).copied().collect()
    }
}

impl candle_core::CustomOp2 for QuasistaticProjection {
    fn name(&self) -> &'static str {
        "quasistatic-projection"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (x, m) = (f32_slice(self.name(), s1, l1)?, f32_slice(self.name(), s2, l2)?);
        let solutions = self.solve(x, m)?;
        let flat: Vec<f64> = solutions.iter().flat_map(|s| s.positions().iter().copied()).collect();
        let out = convert::f64_to_f32("quasistatic projection output", &flat).map_err(op_error)?;
        store_cached(&self.last, Self::inputs(x, m), solutions);
        Ok((CpuStorage::F32(out), l1.shape().clone()))
    }

    fn bwd(
        &self,
        predictions: &Tensor,
        mu: &Tensor,
        _res: &Tensor,
        grad_res: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let x: Vec<f32> = predictions.flatten_all()?.to_vec1()?;
        let m: Vec<f32> = mu.flatten_all()?.to_vec1()?;
        let solutions = match take_cached(&self.last, &Self::inputs(&x, &m)) {
            Some(s) => s,
            None => self.solve(&x, &m)?,
        };
        let g: Vec<f32> = grad_res.flatten_all()?.to_vec1()?;
        let g = convert::f32_to_f64("quasistatic projection output gradient", &g).map_err(op_error)?;
        let back = self
            .layer
            .backward_batch(&solutions, &examples(&g, self.layer.num_vertices()))
            .map_err(op_error)?;
        let d_pred: Vec<f64> = back.iter().flat_map(|b| b.pred.iter().copied()).collect();
        let d_mu: Vec<f64> = if m.len() == 1 {
            vec![back.iter().map(|b| b.mu).sum()]
        } else {
            (0..m.len())
                .map(|i| back.iter().map(|b| b.mu_per_vertex[i]).sum())
                .collect()
        };
        let d_pred = convert::f64_to_f32("quasistatic projection input gradient", &d_pred).map_err(op_error)?;
        let d_mu = convert::f64_to_f32("quasistatic projection mu gradient", &d_mu).map_err(op_error)?;
        Ok((
            Some(Tensor::from_vec(d_pred, predictions.shape(), predictions.device())?),
            Some(Tensor::from_vec(d_mu, mu.shape(), mu.device())?),
        ))
    }
}

/// Geng et al.'s inextensibility projection (§4, the edge-length SOCP) as a candle op over a
/// batch: predictions `[B, V, 3]` (f32, metres) to the nearest shapes `r*` whose edges are
/// at most `1 + ε` times their rest length. The solves run in f64 in weft-proj, one example
/// per thread; the backward pass is weft-proj's (Eq. 11), on the forward pass's solutions
/// when it follows it with the same inputs (as [`QuasistaticProjection`]).
///
/// Warm starts (training): [`InextensibilityProjection::apply_keyed`] names each example, and
/// its solve starts from that example's previous solution and active set
/// (`InextensibilityLayer::forward_from`).
#[derive(Debug, Clone)]
pub struct InextensibilityProjection {
    layer: Arc<weft_proj::InextensibilityLayer>,
    keys: Option<Arc<Vec<usize>>>,
    previous: Arc<weft_proj::WarmStarts<usize, weft_proj::SocpSolution>>,
    last: ForwardCache<weft_proj::SocpSolution>,
}

impl InextensibilityProjection {
    pub fn new(layer: Arc<weft_proj::InextensibilityLayer>) -> Self {
        Self {
            layer,
            keys: None,
            previous: Arc::default(),
            last: Arc::default(),
        }
    }

    /// `r*` for predictions `[B, V, 3]`, differentiable.
    pub fn apply(&self, predictions: &Tensor) -> crate::error::Result<Tensor> {
        self.check(predictions)?;
        let op = Self {
            keys: None,
            ..self.clone()
        };
        Ok(predictions.contiguous()?.apply_op1(op)?)
    }

    /// [`apply`](Self::apply) with example `keys[b]` for batch entry `b`: each solve starts
    /// from the solution this op last found for the same key.
    pub fn apply_keyed(&self, predictions: &Tensor, keys: &[usize]) -> crate::error::Result<Tensor> {
        self.check(predictions)?;
        let op = Self {
            keys: Some(example_keys("inextensibility projection keys", predictions, keys)?),
            ..self.clone()
        };
        Ok(predictions.contiguous()?.apply_op1(op)?)
    }

    fn check(&self, predictions: &Tensor) -> crate::error::Result<()> {
        let v = self.layer.num_vertices();
        let (_, pv, three) = predictions.dims3()?;
        if pv != v || three != 3 {
            return Err(crate::error::Error::Shape {
                what: "inextensibility projection input",
                expected: format!("[B, {v}, 3]"),
                got: format!("{:?}", predictions.dims()),
            });
        }
        Ok(())
    }

    fn solve(&self, predictions: &[f32]) -> candle_core::Result<Vec<weft_proj::SocpSolution>> {
        let x = convert::f32_to_f64("inextensibility projection input", predictions).map_err(op_error)?;
        let preds = examples(&x, self.layer.num_vertices());
        let previous = self
            .previous
            .starts(self.keys.as_deref().map(Vec::as_slice), preds.len());
        let starts: Vec<Option<&weft_proj::SocpSolution>> = previous.iter().map(Option::as_ref).collect();
        let solutions: Vec<weft_proj::SocpSolution> = self
            .layer
            .forward_batch_from(&preds, &starts)
            .into_iter()
            .map(|r| r.map(|(solution, _)| solution).map_err(op_error))
            .collect::<candle_core::Result<_>>()?;
        self.previous.remember(
            self.keys.as_deref().map(Vec::as_slice),
            solutions.iter().map(weft_proj::SocpSolution::warm_start),
        );
        Ok(solutions)
    }
}

impl CustomOp1 for InextensibilityProjection {
    fn name(&self) -> &'static str {
        "inextensibility-projection"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let x = f32_slice(self.name(), s, l)?;
        let solutions = self.solve(x)?;
        let flat: Vec<f64> = solutions.iter().flat_map(|s| s.positions().iter().copied()).collect();
        let out = convert::f64_to_f32("inextensibility projection output", &flat).map_err(op_error)?;
        store_cached(&self.last, x.to_vec(), solutions);
        Ok((CpuStorage::F32(out), l.shape().clone()))
    }

    fn bwd(&self, predictions: &Tensor, _res: &Tensor, grad_res: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let x: Vec<f32> = predictions.flatten_all()?.to_vec1()?;
        let solutions = match take_cached(&self.last, &x) {
            Some(s) => s,
            None => self.solve(&x)?,
        };
        let g: Vec<f32> = grad_res.flatten_all()?.to_vec1()?;
        let g = convert::f32_to_f64("inextensibility projection output gradient", &g).map_err(op_error)?;
        let back = self
            .layer
            .backward_batch(&solutions, &examples(&g, self.layer.num_vertices()))
            .map_err(op_error)?;
        let flat: Vec<f64> = back.concat();
        let out = convert::f64_to_f32("inextensibility projection input gradient", &flat).map_err(op_error)?;
        Ok(Some(Tensor::from_vec(out, predictions.shape(), predictions.device())?))
    }
}
