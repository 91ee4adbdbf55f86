//! NNWarp (Luo et al.): a node-wise MLP that turns a linear FEM displacement into the
//! nonlinear material's (§3–5).
//!
//! For each free node the network sees seven numbers:
//! - the three rotation-invariant scalars of its linear displacement `ũ_i` and local
//!   rotation vector `w_i`, in the frame that takes `ũ_i` to +y and `w_i` into the
//!   xy-plane (§5, Fig. 12; `weft_sim::warp::aligned_kinematics`);
//! - geodesic, potential and digression (§3.3);
//! - the Poisson ratio.
//!
//! It answers the correction `δu_i` in that aligned frame, so `u_i = ũ_i + Q_iᵀ δu_i`.
//! Everything is measured on the body scaled into the unit sphere, as the network was
//! trained; [`WarpContext`] does the scaling, so a body of any size can be warped.
//!
//! Training runs in candle ([`WarpMlp`]); the runtime ([`NnWarp`]) evaluates the same
//! weights outside it ([`NodeMlp`]: one faer product per layer over all nodes), because
//! 16-wide layers are far below the size at which a tensor library's per-call overhead
//! pays off. The bench `weft-nn/benches/nnwarp_correction.rs` measures both on the beam's
//! 637 nodes: 0.78 ms in candle, 0.042 ms in the runtime (docs/BENCHMARKS.md).

use std::sync::Arc;

use candle_core::Tensor;
use nalgebra::{Rotation3, Vector3};
use rayon::prelude::*;
use weft_mesh::TetMesh;
use weft_sim::warp::{FieldDirection, NodalGradients, aligned_kinematics, contextual_features};

use crate::error::{Error, Result};
use crate::params::{Init, Params};

/// Inputs per node: three kinematic scalars, geodesic, potential, digression, ν.
pub const INPUTS: usize = 7;
/// Outputs per node: the correction in the aligned frame.
pub const OUTPUTS: usize = 3;

/// What stays fixed while one body is warped under one field: the gradient fit, the
/// contextual features, the free nodes, ν and the unit-sphere scale.
#[derive(Debug, Clone)]
pub struct WarpContext {
    gradients: Arc<NodalGradients>,
    context: Vec<[f64; 3]>,
    free: Vec<usize>,
    poisson: f64,
    /// Lengths of the body times this are unit-sphere lengths.
    scale: f64,
}

/// The per-node inputs of one linear solution: the aligning rotations and features of the
/// free nodes (in [`WarpContext::free_nodes`] order).
#[derive(Debug, Clone)]
pub struct NodeInputs {
    pub rotations: Vec<Rotation3<f64>>,
    pub features: Vec<[f64; INPUTS]>,
    /// Each free node's local rotation vector `w_i` (what the kinematic inputs were
    /// computed from).
    pub rotation_vectors: Vec<Vector3<f64>>,
}

impl WarpContext {
    /// `mesh` in its own units, its `anchors`, the field's direction and ν.
    pub fn new(mesh: &TetMesh, anchors: &[usize], field: FieldDirection, poisson: f64) -> Result<Self> {
        let (_, scale) = weft_sim::warp::unit_sphere_normalization(mesh.positions());
        let gradients = Arc::new(NodalGradients::new(mesh)?);
        Self::with_gradients(mesh, gradients, anchors, field, poisson, scale)
    }

    /// As [`WarpContext::new`], sharing a gradient fit of the same mesh and with the scale given.
    pub fn with_gradients(
        mesh: &TetMesh,
        gradients: Arc<NodalGradients>,
        anchors: &[usize],
        field: FieldDirection,
        poisson: f64,
        scale: f64,
    ) -> Result<Self> {
        if !(poisson.is_finite() && (0.0..0.5).contains(&poisson)) {
            return Err(Error::InvalidParameter {
                name: "Poisson ratio",
                value: poisson.to_string(),
                reason: "must lie in [0, 0.5)",
            });
        }
        let context = contextual_features(mesh, anchors, field)?;
        let mut is_anchor = vec![false; mesh.num_vertices()];
        for &a in anchors {
            is_anchor[a] = true;
        }
        Ok(Self {
            gradients,
            context,
            free: (0..mesh.num_vertices()).filter(|&i| !is_anchor[i]).collect(),
            poisson,
            scale,
        })
    }

    pub fn free_nodes(&self) -> &[usize] {
        &self.free
    }

    pub fn num_nodes(&self) -> usize {
        self.context.len()
    }

    /// Refuses displacements of the wrong length or with a non-finite entry.
    fn check(&self, linear: &[f64]) -> Result<()> {
        if linear.len() != 3 * self.num_nodes() {
            return Err(Error::Shape {
                what: "linear displacements",
                expected: format!("{} values", 3 * self.num_nodes()),
                got: format!("{}", linear.len()),
            });
        }
        if let Some(index) = linear.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "linear displacements",
                index,
            });
        }
        Ok(())
    }

    /// Node `i`'s aligning rotation `Q_i`, its seven inputs and its rotation vector `w_i`.
    fn node_input(&self, linear: &[f64], i: usize) -> (Rotation3<f64>, [f64; INPUTS], Vector3<f64>) {
        // The displacement gradient is dimensionless: the same at any scale.
        let w = self.gradients.rotation_vector(linear, i);
        let u = Vector3::new(linear[3 * i], linear[3 * i + 1], linear[3 * i + 2]) * self.scale;
        let (q, k) = aligned_kinematics(&u, &w);
        let c = self.context[i];
        (q, [k[0], k[1], k[2], c[0], c[1], c[2], self.poisson], w)
    }

    /// The network's inputs for the linear displacements `linear` (flat, the body's units).
    pub fn inputs(&self, linear: &[f64]) -> Result<NodeInputs> {
        self.check(linear)?;
        let (rotations, (features, rotation_vectors)) = self
            .free
            .par_iter()
            .with_min_len(256)
            .map(|&i| {
                let (q, x, w) = self.node_input(linear, i);
                (q, (x, w))
            })
            .unzip();
        Ok(NodeInputs {
            rotations,
            features,
            rotation_vectors,
        })
    }

    /// Training pairs of one frame: inputs and the aligned correction `Q_i (u_i − ũ_i)`
    /// in unit-sphere units, for every free node.
    pub fn pairs(&self, linear: &[f64], nonlinear: &[f64]) -> Result<(Vec<[f64; INPUTS]>, Vec<[f64; OUTPUTS]>)> {
        if nonlinear.len() != linear.len() {
            return Err(Error::Shape {
                what: "registered displacements",
                expected: format!("{} values", linear.len()),
                got: format!("{}", nonlinear.len()),
            });
        }
        let inputs = self.inputs(linear)?;
        let targets = self
            .free
            .iter()
            .zip(&inputs.rotations)
            .map(|(&i, q)| {
                let d = Vector3::new(
                    nonlinear[3 * i] - linear[3 * i],
                    nonlinear[3 * i + 1] - linear[3 * i + 1],
                    nonlinear[3 * i + 2] - linear[3 * i + 2],
                ) * self.scale;
                let a = q * d;
                [a.x, a.y, a.z]
            })
            .collect();
        Ok((inputs.features, targets))
    }
}

/// Per-column means and standard deviations of inputs and outputs, fitted on the training
/// pairs; the network sees and answers standardised values.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Standardization {
    pub input_mean: [f64; INPUTS],
    pub input_std: [f64; INPUTS],
    pub output_mean: [f64; OUTPUTS],
    pub output_std: [f64; OUTPUTS],
}

fn mean_std<const N: usize>(rows: &[[f64; N]]) -> ([f64; N], [f64; N]) {
    let n = rows.len().max(1) as f64;
    let mut mean = [0.0; N];
    for r in rows {
        for d in 0..N {
            mean[d] += r[d] / n;
        }
    }
    let mut std = [0.0; N];
    for r in rows {
        for d in 0..N {
            std[d] += (r[d] - mean[d]).powi(2) / n;
        }
    }
    // A constant column (one Poisson ratio, one field kind) is passed through unscaled.
    (mean, std.map(|v| if v.sqrt() > 1e-12 { v.sqrt() } else { 1.0 }))
}

impl Standardization {
    pub fn fit(inputs: &[[f64; INPUTS]], outputs: &[[f64; OUTPUTS]]) -> Result<Self> {
        if inputs.is_empty() || inputs.len() != outputs.len() {
            return Err(Error::InvalidParameter {
                name: "training pairs",
                value: format!("{} inputs, {} outputs", inputs.len(), outputs.len()),
                reason: "need as many outputs as inputs, and at least one",
            });
        }
        let (input_mean, input_std) = mean_std(inputs);
        let (output_mean, output_std) = mean_std(outputs);
        Ok(Self {
            input_mean,
            input_std,
            output_mean,
            output_std,
        })
    }

    pub fn input(&self, x: &[f64; INPUTS]) -> [f64; INPUTS] {
        std::array::from_fn(|d| (x[d] - self.input_mean[d]) / self.input_std[d])
    }

    pub fn output(&self, y: &[f64; OUTPUTS]) -> [f64; OUTPUTS] {
        std::array::from_fn(|d| (y[d] - self.output_mean[d]) / self.output_std[d])
    }

    pub fn unoutput(&self, y: &[f64; OUTPUTS]) -> [f64; OUTPUTS] {
        std::array::from_fn(|d| y[d] * self.output_std[d] + self.output_mean[d])
    }
}

/// NNWarp §5's network sizes: two hidden layers of 16 for co-rotational and Neo-Hookean,
/// three for StVK.
pub fn hidden_layers(material: &str) -> Vec<usize> {
    if material == "stvk" { vec![16; 3] } else { vec![16; 2] }
}

/// The kinematic inputs (the first three) that mean "no displacement".
const KINEMATIC: usize = 3;

/// The MLP in candle: tanh hidden layers, a linear output (§5), with one addition: the
/// correction is `net(x) − net(x₀)`, `x₀` being `x` with the three kinematic inputs at
/// zero. A node that does not move is then never corrected, whatever the contextual
/// features. Without it the trained networks moved nodes of a barely loaded body by many
/// times its own displacement (docs/NNWARP.md, *Zero correction at rest*).
#[derive(Debug, Clone)]
pub struct WarpMlp {
    layers: Vec<(Tensor, Tensor)>,
    /// Standardised zero kinematics `[1, 3]` and the standardised zero output `[3]`.
    zero_input: Tensor,
    zero_output: Tensor,
}

impl WarpMlp {
    /// Creates `layer{k}.w` `[in, out]` and `layer{k}.b` in `params`, Glorot-uniform
    /// (the initialisation made for tanh), for inputs and outputs standardised by
    /// `standardization`.
    pub fn new(params: &mut Params, hidden: &[usize], standardization: &Standardization) -> Result<Self> {
        let mut widths = vec![INPUTS];
        widths.extend(hidden);
        widths.push(OUTPUTS);
        if widths.iter().any(|&w| w == 0 || w > MAX_WIDTH) {
            return Err(Error::InvalidParameter {
                name: "NNWarp hidden widths",
                value: format!("{hidden:?}"),
                reason: "each must lie in 1..=64",
            });
        }
        let layers = widths
            .windows(2)
            .enumerate()
            .map(|(k, w)| {
                let bound = (6.0 / (w[0] + w[1]) as f64).sqrt();
                Ok((
                    params.create(&format!("layer{k}.w"), &[w[0], w[1]], Init::Uniform(bound))?,
                    params.create(&format!("layer{k}.b"), &[w[1]], Init::Zeros)?,
                ))
            })
            .collect::<Result<_>>()?;
        let device = params.device();
        let zero = standardization.input(&[0.0; INPUTS]);
        let zero_input = Tensor::from_vec(
            zero[..KINEMATIC].iter().map(|&v| v as f32).collect::<Vec<_>>(),
            (1, KINEMATIC),
            device,
        )?;
        let out = standardization.output(&[0.0; OUTPUTS]);
        let zero_output = Tensor::from_vec(out.iter().map(|&v| v as f32).collect::<Vec<_>>(), OUTPUTS, device)?;
        Ok(Self {
            layers,
            zero_input,
            zero_output,
        })
    }

    fn net(&self, x: &Tensor) -> Result<Tensor> {
        let mut h = x.clone();
        for (k, (w, b)) in self.layers.iter().enumerate() {
            h = h.broadcast_matmul(w)?.broadcast_add(b)?;
            if k + 1 < self.layers.len() {
                h = h.tanh()?;
            }
        }
        Ok(h)
    }

    /// `[N, 7]` standardised inputs → `[N, 3]` standardised corrections.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let n = x.dim(0)?;
        let at_rest = Tensor::cat(
            &[
                self.zero_input.broadcast_as((n, KINEMATIC))?,
                x.narrow(1, KINEMATIC, INPUTS - KINEMATIC)?,
            ],
            1,
        )?;
        Ok((self.net(x)? - self.net(&at_rest)?)?.broadcast_add(&self.zero_output)?)
    }

    /// The same weights for the plain-Rust runtime.
    pub fn to_node_mlp(&self, standardization: Standardization) -> Result<NodeMlp> {
        let layers = self
            .layers
            .iter()
            .map(|(w, b)| {
                let (n_in, n_out) = w.dims2()?;
                Ok(DenseLayer {
                    n_in,
                    n_out,
                    weight: w.flatten_all()?.to_vec1::<f32>()?,
                    bias: b.to_vec1::<f32>()?,
                })
            })
            .collect::<Result<_>>()?;
        Ok(NodeMlp {
            layers,
            standardization,
        })
    }
}

/// The widest layer the plain-Rust runtime evaluates on the stack.
const MAX_WIDTH: usize = 64;

#[derive(Debug, Clone)]
struct DenseLayer {
    n_in: usize,
    n_out: usize,
    /// Row-major `[n_in, n_out]`, as candle stores `W` of `x W + b`; f32, as trained.
    weight: Vec<f32>,
    bias: Vec<f32>,
}

/// The trained network as plain Rust: one node at a time, on stack buffers.
#[derive(Debug, Clone)]
pub struct NodeMlp {
    layers: Vec<DenseLayer>,
    pub standardization: Standardization,
}

impl NodeMlp {
    /// The network's raw outputs for standardised input rows (column-major through
    /// [`NodeMlp::net_batch`], the runtime's only implementation of the layers).
    fn net_rows(&self, rows: impl ExactSizeIterator<Item = [f64; INPUTS]>) -> Vec<[f64; OUTPUTS]> {
        let n = rows.len();
        let mut x = vec![0.0f32; n * INPUTS];
        for (k, row) in rows.enumerate() {
            for (d, v) in row.into_iter().enumerate() {
                x[d * n + k] = v as f32;
            }
        }
        let a = self.net_batch(&x, n);
        (0..n)
            .map(|k| std::array::from_fn(|d| f64::from(a[d * n + k])))
            .collect()
    }

    /// The network's raw outputs for `n` nodes at once: `x` holds their standardised
    /// inputs column-major (`x[d * n + k]` is input `d` of node `k`), and so does the
    /// answer. Each layer is one matrix product over all `n` nodes (faer, one thread) and
    /// one pass of [`crate::fast::tanh_f32`] over a contiguous buffer, which vectorises; node by node,
    /// 16-wide layers leave the arithmetic units mostly idle. In f32, as the network was
    /// trained.
    pub fn net_batch(&self, x: &[f32], n: usize) -> Vec<f32> {
        use faer::{Accum, MatMut, MatRef, Par};
        let mut h = x.to_vec();
        for (k, l) in self.layers.iter().enumerate() {
            let mut next = vec![0.0f32; n * l.n_out];
            for (column, b) in next.chunks_mut(n).zip(&l.bias) {
                column.fill(*b);
            }
            faer::linalg::matmul::matmul(
                MatMut::from_column_major_slice_mut(&mut next, n, l.n_out),
                Accum::Add,
                MatRef::from_column_major_slice(&h, n, l.n_in),
                MatRef::from_row_major_slice(&l.weight, l.n_in, l.n_out),
                1.0,
                Par::Seq,
            );
            if k + 1 < self.layers.len() {
                crate::fast::tanh_in_place(&mut next);
            }
            h = next;
        }
        h
    }

    /// The raw output at rest, `net(x₀)`: it depends on the contextual inputs only, so a
    /// runtime computes it once per node ([`NnWarp::new`]).
    pub fn at_rest(&self, x: &[f64; INPUTS]) -> [f64; OUTPUTS] {
        self.at_rest_batch(std::slice::from_ref(x))[0]
    }

    /// [`NodeMlp::at_rest`] of many nodes' raw inputs at once.
    pub fn at_rest_batch(&self, inputs: &[[f64; INPUTS]]) -> Vec<[f64; OUTPUTS]> {
        let zero = self.standardization.input(&[0.0; INPUTS]);
        self.net_rows(inputs.iter().map(|x| {
            let mut x0 = self.standardization.input(x);
            x0[..KINEMATIC].copy_from_slice(&zero[..KINEMATIC]);
            x0
        }))
    }

    /// The corrections (aligned frame, unit-sphere units) of many nodes from their raw
    /// inputs and their [`NodeMlp::at_rest`] outputs: `(net(x) − net(x₀)) σ_out`, every
    /// node through one batched pass of the network.
    pub fn corrections(&self, inputs: &[[f64; INPUTS]], rest: &[[f64; OUTPUTS]]) -> Vec<[f64; OUTPUTS]> {
        let std = &self.standardization.output_std;
        self.net_rows(inputs.iter().map(|x| self.standardization.input(x)))
            .into_iter()
            .zip(rest)
            .map(|(a, r)| std::array::from_fn(|d| (a[d] - r[d]) * std[d]))
            .collect()
    }

    /// The correction from raw inputs `x` and their [`NodeMlp::at_rest`] output.
    pub fn forward_from_rest(&self, x: &[f64; INPUTS], rest: &[f64; OUTPUTS]) -> [f64; OUTPUTS] {
        self.corrections(std::slice::from_ref(x), std::slice::from_ref(rest))[0]
    }

    /// The correction (aligned frame, unit-sphere units) of one node's raw inputs; zero
    /// when the kinematic inputs are.
    pub fn forward(&self, x: &[f64; INPUTS]) -> [f64; OUTPUTS] {
        self.forward_from_rest(x, &self.at_rest(x))
    }
}

/// NNWarp's runtime correction of one body under one field.
#[derive(Debug, Clone)]
pub struct NnWarp {
    context: WarpContext,
    mlp: NodeMlp,
    /// `net(x₀)` per free node (the contextual inputs do not change between frames).
    rest: Vec<[f64; OUTPUTS]>,
}

impl NnWarp {
    pub fn new(context: WarpContext, mlp: NodeMlp) -> Self {
        let inputs: Vec<[f64; INPUTS]> = context
            .free
            .iter()
            .map(|&i| {
                let c = context.context[i];
                [0.0, 0.0, 0.0, c[0], c[1], c[2], context.poisson]
            })
            .collect();
        let rest = mlp.at_rest_batch(&inputs);
        Self { context, mlp, rest }
    }

    pub fn context(&self) -> &WarpContext {
        &self.context
    }

    /// `u = ũ + Qᵀ δu` at every free node (anchored nodes keep their linear value).
    pub fn warp(&self, linear: &[f64]) -> Result<Vec<f64>> {
        Ok(self.warp_with_rotations(linear)?.0)
    }

    /// [`NnWarp::warp`], also returning every node's local rotation vector `w_i` of
    /// `linear` (zero at the anchors, which no load moves), for the next frame's
    /// [`weft_sim::warp::rotate_loads_to_rest`].
    pub fn warp_with_rotations(&self, linear: &[f64]) -> Result<(Vec<f64>, Vec<Vector3<f64>>)> {
        self.context.check(linear)?;
        // Inputs, the network as one matrix product per layer, back to the world frame:
        // on the calling thread for a small body, in chunks on all threads for a large one.
        let free = &self.context.free;
        let mut per_node = vec![(Vector3::zeros(), Vector3::zeros()); free.len()];
        if free.len() < PARALLEL_NODES {
            self.correct_nodes(linear, 0, &mut per_node);
        } else {
            per_node
                .par_chunks_mut(CHUNK_NODES)
                .enumerate()
                .for_each(|(c, out)| self.correct_nodes(linear, c * CHUNK_NODES, out));
        }
        let mut out = linear.to_vec();
        let mut w = vec![Vector3::zeros(); self.context.num_nodes()];
        for (&i, (d, wi)) in self.context.free.iter().zip(&per_node) {
            for k in 0..3 {
                out[3 * i + k] += d[k];
            }
            w[i] = *wi;
        }
        if let Some(index) = out.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                what: "NNWarp displacements",
                index,
            });
        }
        Ok((out, w))
    }
}

impl NnWarp {
    /// The correction `Q_iᵀ δu_i` (the body's units) and the rotation vector `w_i` of the
    /// free nodes `start..start + out.len()` (in [`WarpContext::free_nodes`] order): their
    /// inputs, the network on all of them at once, and back to the world frame.
    fn correct_nodes(&self, linear: &[f64], start: usize, out: &mut [(Vector3<f64>, Vector3<f64>)]) {
        let n = out.len();
        let free = &self.context.free[start..start + n];
        let rest = &self.rest[start..start + n];
        let mut x = Vec::with_capacity(n);
        let mut q = Vec::with_capacity(n);
        for (slot, &i) in out.iter_mut().zip(free) {
            let (qi, xi, wi) = self.context.node_input(linear, i);
            x.push(xi);
            q.push(qi);
            slot.1 = wi;
        }
        let d = self.mlp.corrections(&x, rest);
        for ((slot, d), q) in out.iter_mut().zip(d).zip(&q) {
            slot.0 = q.inverse() * Vector3::from(d) / self.context.scale;
        }
    }
}

/// Free nodes below which the correction runs on the calling thread: on the 637-node beam
/// waking a second thread costs more than it saves (docs/BENCHMARKS.md).
const PARALLEL_NODES: usize = 2048;
/// Free nodes per parallel task of the correction.
const CHUNK_NODES: usize = 1024;

/// One frame of [`NnWarpSimulation`].
#[derive(Debug, Clone)]
pub struct NnWarpFrame {
    /// The linear solve's displacements `ũ` (m, flat).
    pub linear: Vec<f64>,
    /// NNWarp's displacements `u` (m, flat).
    pub warped: Vec<f64>,
    /// Rotating the loads to the rest frames and the pre-factorised solve (s).
    pub solve_seconds: f64,
    /// The node-wise correction (s).
    pub warp_seconds: f64,
}

/// NNWarp's runtime on a volumetric scene (§6): linear elasticity with a constant,
/// pre-factorised system, then the node-wise correction of every frame.
///
/// A dynamic scene (implicit Euler, Newmark or dynamic linear) runs as backward Euler
/// with the scene's time step and Rayleigh damping; a static one applies its load in
/// `frames` equal increments. As in stiffness warping, each node's load is first rotated
/// back to its rest orientation by the local rotation of the previous frame's linear
/// displacement ([`weft_sim::warp::loads_in_rest_frames`]); only then is the network's
/// training target, `f_int(u) = 𝓡 K ũ`, the nonlinear body under the actual load.
#[derive(Debug)]
pub struct NnWarpSimulation {
    linear: weft_sim::PrefactorizedLinear,
    warp: NnWarp,
    forces: Vec<f64>,
    frames: usize,
    frame: usize,
    /// The last frame's local rotation vectors (zero at rest), from its correction.
    rotations: Vec<Vector3<f64>>,
}

/// A body for [`NnWarpSimulation::from_body`]: everything NNWarp's runtime needs, without
/// a nonlinear scene.
#[derive(Debug, Clone)]
pub struct WarpBody<'a> {
    pub mesh: &'a TetMesh,
    pub anchors: &'a [usize],
    /// Young's modulus (Pa) and Poisson ratio of the linear material.
    pub young: f64,
    pub poisson: f64,
    /// kg/m³.
    pub density: f64,
    /// External forces (N, flat): the full load of a static run, the constant load of a
    /// dynamic one.
    pub forces: &'a [f64],
    pub solve: weft_sim::LinearSolve,
    /// The field the contextual features are measured along.
    pub field: FieldDirection,
    /// Load increments of a static run (ignored by a dynamic one).
    pub frames: usize,
}

impl NnWarpSimulation {
    /// The linear twin of `reference` (its mesh, anchors, loads and time step, with the
    /// linear material of its Lamé parameters), corrected by `mlp`.
    pub fn new(reference: &weft_sim::VolumeSimulation, mlp: NodeMlp) -> Result<Self> {
        use weft_sim::scenes::volume::VolumeSolve;
        use weft_sim::{LinearSolve, RayleighDamping};
        let scene = reference.scene();
        let solve = match scene.solve {
            VolumeSolve::ImplicitEuler { dt } => LinearSolve::Dynamic {
                dt,
                damping: RayleighDamping::NONE,
            },
            VolumeSolve::Newmark {
                dt,
                rayleigh_mass,
                rayleigh_stiffness,
            }
            | VolumeSolve::DynamicLinear {
                dt,
                rayleigh_mass,
                rayleigh_stiffness,
            } => LinearSolve::Dynamic {
                dt,
                damping: RayleighDamping {
                    mass: rayleigh_mass,
                    stiffness: rayleigh_stiffness,
                },
            },
            VolumeSolve::Quasistatic | VolumeSolve::StaticLinear => LinearSolve::Static,
        };
        Self::from_body(
            WarpBody {
                mesh: reference.mesh(),
                anchors: reference.anchors(),
                young: scene.young,
                poisson: scene.poisson,
                density: scene.density,
                forces: reference.external_forces(),
                solve,
                field: field_direction(scene)?,
                frames: scene.frames,
            },
            mlp,
        )
    }

    /// NNWarp's runtime on `body`, corrected by `mlp`.
    pub fn from_body(body: WarpBody<'_>, mlp: NodeMlp) -> Result<Self> {
        let mesh = body.mesh;
        let lame = weft_sim::energies::LameParameters::from_young_poisson(body.young, body.poisson)?;
        let linear_energy = weft_sim::energies::TetElasticity::new(mesh, weft_sim::energies::Material::Linear, lame)?;
        let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), body.density);
        let fixed = weft_sim::anchors::fixed_dofs(mesh.num_vertices(), body.anchors)?;
        let linear =
            weft_sim::PrefactorizedLinear::new(&mesh.flat_positions(), &[&linear_energy], masses, fixed, body.solve)?;
        if body.forces.len() != 3 * mesh.num_vertices() {
            return Err(Error::Shape {
                what: "external forces",
                expected: format!("{} values", 3 * mesh.num_vertices()),
                got: body.forces.len().to_string(),
            });
        }
        let gradients = Arc::new(NodalGradients::new(mesh)?);
        let (_, scale) = weft_sim::warp::unit_sphere_normalization(mesh.positions());
        let context = WarpContext::with_gradients(mesh, gradients, body.anchors, body.field, body.poisson, scale)?;
        Ok(Self {
            linear,
            warp: NnWarp::new(context, mlp),
            forces: body.forces.to_vec(),
            frames: body.frames.max(1),
            frame: 0,
            rotations: vec![Vector3::zeros(); mesh.num_vertices()],
        })
    }

    pub fn linear(&self) -> &weft_sim::PrefactorizedLinear {
        &self.linear
    }

    pub fn warp(&self) -> &NnWarp {
        &self.warp
    }

    /// Advances one frame.
    pub fn step(&mut self) -> Result<NnWarpFrame> {
        self.frame += 1;
        let t = std::time::Instant::now();
        let load: Vec<f64> = match self.linear.mode() {
            weft_sim::LinearSolve::Static => {
                let s = self.frame.min(self.frames) as f64 / self.frames as f64;
                self.forces.iter().map(|f| f * s).collect()
            }
            weft_sim::LinearSolve::Dynamic { .. } => self.forces.clone(),
        };
        // The rotations of the previous frame's linear displacement, which its correction
        // fitted: the same as `loads_in_rest_frames` on it, without a second fit.
        let load = weft_sim::warp::rotate_loads_to_rest(&self.rotations, &load)?;
        self.linear.step(&load, &[])?;
        let solve_seconds = t.elapsed().as_secs_f64();
        let linear = self.linear.displacements().to_vec();
        let t = std::time::Instant::now();
        let (warped, rotations) = self.warp.warp_with_rotations(&linear)?;
        self.rotations = rotations;
        Ok(NnWarpFrame {
            linear,
            warped,
            solve_seconds,
            warp_seconds: t.elapsed().as_secs_f64(),
        })
    }
}

/// The field direction the contextual features need, from a scene's loads: its force
/// field, or gravity.
pub fn field_direction(scene: &weft_sim::VolumeScene) -> Result<FieldDirection> {
    use weft_sim::scenes::volume::ForceField;
    match (&scene.force_field, scene.gravity) {
        (Some(ForceField::Directional { direction, .. }), _) => {
            Ok(FieldDirection::Directional(Vector3::from(*direction)))
        }
        (Some(ForceField::Circular { center, axis, .. }), _) => Ok(FieldDirection::Circular {
            center: Vector3::from(*center),
            axis: Vector3::from(*axis),
        }),
        (None, Some(g)) if g.iter().any(|v| *v != 0.0) => Ok(FieldDirection::Directional(Vector3::from(g))),
        _ => Err(Error::InvalidParameter {
            name: "scene",
            value: scene.name.clone(),
            reason: "has no load (gravity or a force field) for NNWarp to warp",
        }),
    }
}

/// The training pairs of one split of a dataset: every free node of every frame after
/// the first (the rest frame has nothing to correct).
pub fn collect_pairs(
    dataset: &weft_data::WarpDataset,
    split: &str,
) -> Result<(Vec<[f64; INPUTS]>, Vec<[f64; OUTPUTS]>)> {
    let gradients = Arc::new(NodalGradients::new(&dataset.body)?);
    let mut inputs = Vec::new();
    let mut outputs = Vec::new();
    for s in dataset.sequences.iter().filter(|s| s.split == split) {
        // The dataset's body is already in the unit sphere: scale 1.
        let ctx = WarpContext::with_gradients(
            &dataset.body,
            gradients.clone(),
            &dataset.anchors,
            s.field,
            s.poisson,
            1.0,
        )?;
        for (lin, non) in s.linear.iter().zip(&s.nonlinear).skip(1) {
            let (x, y) = ctx.pairs(lin, non)?;
            inputs.extend(x);
            outputs.extend(y);
        }
    }
    Ok((inputs, outputs))
}

/// How an NNWarp network is trained (NNWarp §5: Adam, learning rate 1e-3, batch 1024,
/// about 10 epochs).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WarpTrainingConfig {
    /// The material the network was trained for (the dataset's array name, e.g.
    /// `neo-hookean`); set by the trainer.
    pub material: String,
    /// Hidden widths; empty means the paper's for the material ([`hidden_layers`]).
    pub hidden: Vec<usize>,
    pub adam: crate::adam::AdamSettings,
    pub batch: usize,
    pub epochs: usize,
    pub seed: u64,
    /// The learning-rate schedule and stopping rules (constant by default, as NNWarp §5).
    pub schedule: crate::trainer::Schedule,
}

impl WarpTrainingConfig {
    /// Checks every field before any work: a typed error naming the first bad one.
    pub fn validate(&self) -> Result<()> {
        use crate::trainer::{MAX_BATCH, MAX_EPOCHS, check_adam, check_count};
        check_count("hidden (number of layers)", self.hidden.len().max(1), 64)?;
        for (i, &w) in self.hidden.iter().enumerate() {
            check_count(&format!("hidden[{i}]"), w, 4096)?;
        }
        check_count("epochs", self.epochs, MAX_EPOCHS)?;
        check_count("batch", self.batch, MAX_BATCH)?;
        check_adam("adam", &self.adam)?;
        self.schedule.validate("schedule")
    }

    /// The trainer's part of the configuration.
    pub fn trainer(&self) -> crate::trainer::TrainerConfig {
        crate::trainer::TrainerConfig {
            epochs: self.epochs,
            batch: self.batch,
            seed: self.seed,
            schedule: self.schedule,
        }
    }
}

impl Default for WarpTrainingConfig {
    fn default() -> Self {
        Self {
            material: String::new(),
            hidden: Vec::new(),
            adam: crate::adam::AdamSettings::default(),
            batch: 1024,
            epochs: 10,
            seed: 0,
            schedule: crate::trainer::Schedule::default(),
        }
    }
}

/// Standardised pairs as `[N, 7]` and `[N, 3]` f32 tensors.
pub fn pair_tensors(
    inputs: &[[f64; INPUTS]],
    outputs: &[[f64; OUTPUTS]],
    standardization: &Standardization,
    device: &candle_core::Device,
) -> Result<(Tensor, Tensor)> {
    let x: Vec<f32> = inputs
        .iter()
        .flat_map(|r| standardization.input(r).map(|v| v as f32))
        .collect();
    let y: Vec<f32> = outputs
        .iter()
        .flat_map(|r| standardization.output(r).map(|v| v as f32))
        .collect();
    Ok((
        Tensor::from_vec(x, (inputs.len(), INPUTS), device)?,
        Tensor::from_vec(y, (outputs.len(), OUTPUTS), device)?,
    ))
}

/// Mean squared error (standardised units) of `mlp` on `x`, `y`, in chunks.
pub fn mean_loss(mlp: &WarpMlp, x: &Tensor, y: &Tensor) -> Result<f64> {
    let n = x.dim(0)?;
    if n == 0 {
        return Ok(0.0);
    }
    let mut sum = 0.0;
    let chunk = 65536;
    for start in (0..n).step_by(chunk) {
        let len = chunk.min(n - start);
        let e = (mlp.forward(&x.narrow(0, start, len)?)? - y.narrow(0, start, len)?)?;
        sum += e
            .sqr()?
            .sum_all()?
            .to_dtype(candle_core::DType::F64)?
            .to_scalar::<f64>()?;
    }
    Ok(sum / (n * OUTPUTS) as f64)
}

/// Root-mean-square error (unit-sphere units, over nodes and the three components) of
/// the runtime's correction [`NodeMlp::forward`] against the aligned targets of
/// [`WarpContext::pairs`]. Unlike the trainer's validation score (standardised units,
/// fitted on each run's own training pairs), it compares networks trained on different
/// data: the data-size study's curves use it.
pub fn correction_rms(mlp: &NodeMlp, inputs: &[[f64; INPUTS]], targets: &[[f64; OUTPUTS]]) -> Result<f64> {
    if inputs.len() != targets.len() || inputs.is_empty() {
        return Err(Error::Shape {
            what: "correction targets",
            expected: format!("{} pairs, at least one", inputs.len()),
            got: format!("{}", targets.len()),
        });
    }
    let chunk = 16384;
    let squares: f64 = inputs
        .par_chunks(chunk)
        .zip(targets.par_chunks(chunk))
        .map(|(x, y)| {
            // The runtime's correction, net(x) − net(x₀), of every pair.
            let corrections = mlp.corrections(x, &mlp.at_rest_batch(x));
            corrections
                .iter()
                .zip(y)
                .map(|(c, t)| (0..OUTPUTS).map(|d| (c[d] - t[d]).powi(2)).sum::<f64>())
                .sum::<f64>()
        })
        .sum();
    let rms = (squares / (inputs.len() * OUTPUTS) as f64).sqrt();
    if !rms.is_finite() {
        return Err(Error::NonFinite {
            what: "correction error",
            index: 0,
        });
    }
    Ok(rms)
}

/// NNWarp's MLP trained through [`crate::trainer::Trainer`] on standardised pairs: the
/// loss is the mean squared error of a batch, the validation score that of the
/// validation pairs (standardised units).
#[derive(Debug)]
pub struct WarpTraining<'a> {
    pub mlp: &'a WarpMlp,
    pub params: &'a Params,
    pub x: &'a Tensor,
    pub y: &'a Tensor,
    pub validation_x: &'a Tensor,
    pub validation_y: &'a Tensor,
    pub adam: crate::adam::AdamSettings,
}

impl crate::trainer::Trainable for WarpTraining<'_> {
    fn groups(&self) -> Vec<crate::trainer::Group<'_>> {
        vec![crate::trainer::Group {
            name: "net",
            params: self.params,
            adam: self.adam,
        }]
    }

    fn num_examples(&self) -> usize {
        self.x.dim(0).unwrap_or(0)
    }

    fn batch_loss(&mut self, batch: &[usize], _at: crate::trainer::BatchAt) -> Result<crate::trainer::BatchLoss> {
        let chunk: Vec<u32> = batch.iter().map(|&i| i as u32).collect();
        let idx = Tensor::from_slice(&chunk, chunk.len(), self.x.device())?;
        let (xb, yb) = (self.x.index_select(&idx, 0)?, self.y.index_select(&idx, 0)?);
        let loss = (self.mlp.forward(&xb)? - yb)?.sqr()?.mean_all()?;
        Ok(crate::trainer::BatchLoss::Loss { loss, terms: vec![] })
    }

    fn validation_score(&mut self) -> Result<f64> {
        if self.validation_x.dim(0)? == 0 {
            return Err(Error::InvalidParameter {
                name: "validation split",
                value: "0 pairs".into(),
                reason: "model selection needs validation pairs",
            });
        }
        mean_loss(self.mlp, self.validation_x, self.validation_y)
    }
}

/// A trained model directory written by `cargo xtask train nnwarp`: `config.json` (the
/// training configuration, hidden widths resolved), `standardization.json` and the
/// trainer's run, loaded at its best validation weights.
pub fn load_model(dir: &std::path::Path) -> Result<(WarpTrainingConfig, NodeMlp)> {
    crate::checkpoint::check_model_kind(dir, "nnwarp")?;
    let read = |name: &str| -> Result<String> {
        let path = dir.join(name);
        std::fs::read_to_string(&path).map_err(|source| Error::Io {
            path: path.display().to_string(),
            source,
        })
    };
    let parse_error = |name: &str, e: serde_json::Error| Error::Checkpoint {
        path: dir.join(name).display().to_string(),
        reason: e.to_string(),
    };
    let config: WarpTrainingConfig =
        serde_json::from_str(&read("config.json")?).map_err(|e| parse_error("config.json", e))?;
    let standardization: Standardization =
        serde_json::from_str(&read("standardization.json")?).map_err(|e| parse_error("standardization.json", e))?;
    let mut params = Params::new(&candle_core::Device::Cpu, config.seed);
    let mlp = WarpMlp::new(&mut params, &config.hidden, &standardization)?;
    crate::checkpoint::load_params(&dir.join("best").join("net"), &params)?;
    let node = mlp.to_node_mlp(standardization)?;
    Ok((config, node))
}

/// NNWarp's error measure `rel-error`: the mean over nodes of `|u_i − u*_i|` divided by
/// the largest reference displacement `max_i |u*_i|` (both flat `3V`). Zero when the
/// reference does not move.
pub fn rel_error(predicted: &[f64], reference: &[f64]) -> f64 {
    let n = reference.len() / 3;
    let norm = |v: &[f64], i: usize| (v[3 * i].powi(2) + v[3 * i + 1].powi(2) + v[3 * i + 2].powi(2)).sqrt();
    let max = (0..n).map(|i| norm(reference, i)).fold(0.0f64, f64::max);
    if n == 0 || max == 0.0 {
        return 0.0;
    }
    let diff: Vec<f64> = predicted.iter().zip(reference).map(|(p, r)| p - r).collect();
    (0..n).map(|i| norm(&diff, i)).sum::<f64>() / (n as f64 * max)
}

/// Trains (or continues, up to `config.epochs`) NNWarp's MLP for `dataset`'s material
/// into the model directory `dir`: `config.json` (hidden widths resolved),
/// `standardization.json` (fitted on the training pairs) and the trainer's run. The
/// validation pairs select the kept weights; the test split is not read. Returns the
/// run's state and the pair counts (training, validation).
pub fn train_model(
    dir: &std::path::Path,
    dataset: &weft_data::WarpDataset,
    config: &WarpTrainingConfig,
    observer: &mut dyn crate::trainer::Observer,
) -> Result<(crate::trainer::TrainingState, usize, usize)> {
    let mut config = config.clone();
    if !config.material.is_empty() && config.material != dataset.material {
        return Err(Error::InvalidConfig {
            field: "material".into(),
            value: config.material.clone(),
            reason: "differs from the material read from the dataset",
        });
    }
    config.material = dataset.material.clone();
    if config.hidden.is_empty() {
        config.hidden = hidden_layers(&config.material);
    }
    config.validate()?;
    let (train_x, train_y) = collect_pairs(dataset, "train")?;
    let (val_x, val_y) = collect_pairs(dataset, "validation")?;
    if train_x.is_empty() || val_x.is_empty() {
        return Err(Error::Dataset {
            path: dataset.dir.display().to_string(),
            reason: format!(
                "needs training and validation pairs (it has {} and {})",
                train_x.len(),
                val_x.len()
            ),
        });
    }
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        path: dir.display().to_string(),
        source,
    })?;
    let config_path = dir.join("config.json");
    let standardization_path = dir.join("standardization.json");
    let standardization: Standardization = if crate::trainer::has_run(dir) {
        let stored: WarpTrainingConfig = crate::checkpoint::read_json(&config_path)?;
        let stored = WarpTrainingConfig {
            epochs: config.epochs,
            ..stored
        };
        // The early-stopping patience may grow too (the trainer's rule).
        let mut same = stored.clone();
        same.schedule.early_stopping_patience = config.schedule.early_stopping_patience;
        let continues = stored.trainer().continues_as(&config.trainer()) && same == config;
        crate::checkpoint::check_continues(&config_path, continues, &stored, &config)?;
        crate::checkpoint::read_json(&standardization_path)?
    } else {
        let s = Standardization::fit(&train_x, &train_y)?;
        crate::checkpoint::write_json(&standardization_path, &s)?;
        s
    };
    crate::checkpoint::write_json(&config_path, &config)?;
    let device = candle_core::Device::Cpu;
    let (x, y) = pair_tensors(&train_x, &train_y, &standardization, &device)?;
    let (vx, vy) = pair_tensors(&val_x, &val_y, &standardization, &device)?;
    let mut params = Params::new(&device, config.seed);
    let mlp = WarpMlp::new(&mut params, &config.hidden, &standardization)?;
    let mut training = WarpTraining {
        mlp: &mlp,
        params: &params,
        x: &x,
        y: &y,
        validation_x: &vx,
        validation_y: &vy,
        adam: config.adam,
    };
    let trainer = crate::trainer::Trainer::new(format!("nnwarp/{}", config.material), config.trainer());
    let state = trainer.run(dir, &mut training, observer)?;
    Ok((state, train_x.len(), val_x.len()))
}
