//! NNWarp's runtime: the trained weights evaluated outside candle ([`NodeMlp`]: one faer
//! product per layer over all nodes), the node-wise correction of a linear solution
//! ([`NnWarp`]) and the corrected linear simulation of a volumetric scene
//! ([`NnWarpSimulation`], §6).

use std::sync::Arc;

use nalgebra::Vector3;
use rayon::prelude::*;
use weft_mesh::TetMesh;
use weft_sim::warp::{FieldDirection, NodalGradients};

use super::model::{INPUTS, KINEMATIC, OUTPUTS, Standardization, WarpContext, WarpMlp};
use crate::error::{Error, Result};

impl WarpMlp {
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
    /// The linear solve in the rest frames, the one the training ramp registers
    /// (`weft_sim::warp::register_sequence`).
    linear: weft_sim::warp::RestFrameSolve,
    warp: NnWarp,
    forces: Vec<f64>,
    frames: usize,
    frame: usize,
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
            linear: weft_sim::warp::RestFrameSolve::new(linear),
            warp: NnWarp::new(context, mlp),
            forces: body.forces.to_vec(),
            frames: body.frames.max(1),
            frame: 0,
        })
    }

    pub fn linear(&self) -> &weft_sim::PrefactorizedLinear {
        self.linear.linear()
    }

    pub fn warp(&self) -> &NnWarp {
        &self.warp
    }

    /// Advances one frame.
    pub fn step(&mut self) -> Result<NnWarpFrame> {
        self.frame += 1;
        let t = std::time::Instant::now();
        let load: Vec<f64> = match self.linear.linear().mode() {
            weft_sim::LinearSolve::Static => {
                let s = self.frame.min(self.frames) as f64 / self.frames as f64;
                self.forces.iter().map(|f| f * s).collect()
            }
            weft_sim::LinearSolve::Dynamic { .. } => self.forces.clone(),
        };
        self.step_under(&load, t)
    }

    /// Advances one frame under the world-frame `load` (N, flat) instead of the body's
    /// own: a load that changes from frame to frame, such as the training ramp's.
    pub fn step_with_load(&mut self, load: &[f64]) -> Result<NnWarpFrame> {
        self.frame += 1;
        self.step_under(load, std::time::Instant::now())
    }

    /// The frame under `load`, its solve timed from `t`.
    fn step_under(&mut self, load: &[f64], t: std::time::Instant) -> Result<NnWarpFrame> {
        self.linear.step(load)?;
        let solve_seconds = t.elapsed().as_secs_f64();
        let linear = self.linear.linear().displacements().to_vec();
        let t = std::time::Instant::now();
        let (warped, rotations) = self.warp.warp_with_rotations(&linear)?;
        // The rotations of this frame's linear displacement, which the correction fitted:
        // the same as `loads_in_rest_frames` on it, without a second fit.
        self.linear.set_rotations(rotations)?;
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
