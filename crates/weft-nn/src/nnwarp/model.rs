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
use crate::params::{Init, ParamStore};

/// Inputs per node: three kinematic scalars, geodesic, potential, digression, ν.
pub const INPUTS: usize = 7;
/// Outputs per node: the correction in the aligned frame.
pub const OUTPUTS: usize = 3;

/// What stays fixed while one body is warped under one field: the gradient fit, the
/// contextual features, the free nodes, ν and the unit-sphere scale.
#[derive(Debug, Clone)]
pub struct WarpContext {
    pub(super) gradients: Arc<NodalGradients>,
    pub(super) context: Vec<[f64; 3]>,
    pub(super) free: Vec<usize>,
    pub(super) poisson: f64,
    /// Lengths of the body times this are unit-sphere lengths.
    pub(super) scale: f64,
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
    pub(super) fn check(&self, linear: &[f64]) -> Result<()> {
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
    pub(super) fn node_input(&self, linear: &[f64], i: usize) -> (Rotation3<f64>, [f64; INPUTS], Vector3<f64>) {
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
pub(super) const KINEMATIC: usize = 3;

/// The MLP in candle: tanh hidden layers, a linear output (§5), with one addition: the
/// correction is `net(x) − net(x₀)`, `x₀` being `x` with the three kinematic inputs at
/// zero. A node that does not move is then never corrected, whatever the contextual
/// features. Without it the trained networks moved nodes of a barely loaded body by many
/// times its own displacement (docs/NNWARP.md, *Zero correction at rest*).
#[derive(Debug, Clone)]
pub struct WarpMlp {
    pub(super) layers: Vec<(Tensor, Tensor)>,
    /// Standardised zero kinematics `[1, 3]` and the standardised zero output `[3]`.
    zero_input: Tensor,
    zero_output: Tensor,
}

impl WarpMlp {
    /// Creates `layer{k}.w` `[in, out]` and `layer{k}.b` in `params`, Glorot-uniform
    /// (the initialisation made for tanh), for inputs and outputs standardised by
    /// `standardization`.
    pub fn new(params: &mut ParamStore, hidden: &[usize], standardization: &Standardization) -> Result<Self> {
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
}

/// The widest layer the plain-Rust runtime evaluates on the stack.
const MAX_WIDTH: usize = 64;
