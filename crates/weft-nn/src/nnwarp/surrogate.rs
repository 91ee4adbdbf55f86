//! NNWarp and the linear solves it corrects as proposals of a quasistatic load step, for
//! the guard of `weft_sim::guard::QuasistaticGuard` (docs/GUARD.md, "Quasistatic scenes").
//!
//! Per load step the surrogate answers from the rest state under the step's whole load, as
//! NNWarp's static runtime does (§6): the stiffness-warped linear solve `K ũ = 𝓡(ũ)ᵀ f`
//! iterated to its fixed point (`weft_sim::warp::warped_static_solve`), then the network's
//! node-wise correction ([`NnWarp::warp`]). `warped-linear` stops after the fixed point,
//! `modal-warping` rotates it node by node (`weft_sim::warp::modal_warp`) and `linear` is
//! the plain `K ũ = f`: the baselines the correction is measured against.

use std::sync::Arc;

use weft_mesh::TetMesh;
use weft_sim::LinearSolve;
use weft_sim::PrefactorizedLinear;
use weft_sim::energies::{LameParameters, Material, TetElasticity};
use weft_sim::guard::{LoadStep, QuasistaticSurrogate, SurrogateError};
use weft_sim::warp::{FieldDirection, NodalGradients, modal_warp, unit_sphere_normalization, warped_static_solve};

use super::{NnWarp, NodeMlp, WarpContext};
use crate::Result;

/// What a [`WarpSurrogate`] proposes.
#[derive(Debug, Clone)]
pub enum WarpProposal {
    /// The plain linear solve `K ũ = f`.
    Linear,
    /// The stiffness-warped linear solve's fixed point `ũ` itself: the displacement in
    /// the nodes' rest frames, which NNWarp's correction starts from.
    WarpedLinear,
    /// Modal warping (Choi & Ko) of the warped solve: each node's `ũ_i` turned by its
    /// local rotation, the geometric baseline of the `nnwarp` experiment.
    ModalWarping,
    /// The warped solve corrected by a trained network, whose contextual features are
    /// measured along `field`.
    NnWarp { mlp: Box<NodeMlp>, field: FieldDirection },
}

/// A clamped tet body with a linear material: what every [`WarpSurrogate`] solves on.
#[derive(Debug, Clone, Copy)]
pub struct WarpSurrogateBody<'a> {
    pub mesh: &'a TetMesh,
    pub anchors: &'a [usize],
    /// The linear material's Young's modulus (Pa) and Poisson ratio.
    pub young: f64,
    pub poisson: f64,
    /// The warped fixed point's relative change between solves, and the most solves.
    pub warp_tolerance: f64,
    pub warp_solves: usize,
}

/// NNWarp, the warped or the plain linear solve as a quasistatic surrogate; history-free:
/// each proposal is the body's answer to the step's load from rest.
#[derive(Debug)]
pub struct WarpSurrogate {
    name: &'static str,
    linear: PrefactorizedLinear,
    gradients: Arc<NodalGradients>,
    network: Option<NnWarp>,
    modal: bool,
    warped: bool,
    rest: Vec<f64>,
    warp_tolerance: f64,
    warp_solves: usize,
}

impl WarpSurrogate {
    /// The surrogate `proposal` on `body`: the linear system factorised once here.
    pub fn new(body: &WarpSurrogateBody<'_>, proposal: WarpProposal) -> Result<Self> {
        let mesh = body.mesh;
        let lame = LameParameters::from_young_poisson(body.young, body.poisson)?;
        let elastic = TetElasticity::new(mesh, Material::Linear, lame)?;
        let rest = mesh.flat_positions();
        let fixed = weft_sim::anchors::fixed_dofs(mesh.num_vertices(), body.anchors)?;
        // A static solve reads no masses; they only size the system.
        let masses = vec![1.0; mesh.num_vertices()];
        let linear = PrefactorizedLinear::new(&rest, &[&elastic], masses, fixed, LinearSolve::Static)?;
        let gradients = Arc::new(NodalGradients::new(mesh)?);
        let modal = matches!(proposal, WarpProposal::ModalWarping);
        let (name, warped, network) = match proposal {
            WarpProposal::Linear => ("linear", false, None),
            WarpProposal::WarpedLinear => ("warped-linear", true, None),
            WarpProposal::ModalWarping => ("modal-warping", true, None),
            WarpProposal::NnWarp { mlp, field } => {
                let (_, scale) = unit_sphere_normalization(mesh.positions());
                let context =
                    WarpContext::with_gradients(mesh, gradients.clone(), body.anchors, field, body.poisson, scale)?;
                ("nnwarp", true, Some(NnWarp::new(context, *mlp)))
            }
        };
        Ok(Self {
            name,
            linear,
            gradients,
            network,
            modal,
            warped,
            rest,
            warp_tolerance: body.warp_tolerance,
            warp_solves: body.warp_solves,
        })
    }

    /// The proposed displacement (m, flat) under `load` (N, flat).
    pub fn displacement(&mut self, load: &[f64]) -> Result<Vec<f64>> {
        if self.warped {
            match warped_static_solve(
                &mut self.linear,
                &self.gradients,
                load,
                self.warp_tolerance,
                self.warp_solves,
            ) {
                // A fixed point not reached still leaves the last iterate: a proposal
                // like any other, which the guard judges.
                Ok(_) | Err(weft_sim::Error::WarpNotSettled { .. }) => {}
                Err(e) => return Err(e.into()),
            }
        } else {
            self.linear.step(load, &[])?;
        }
        let u = self.linear.displacements();
        match &self.network {
            Some(net) => net.warp(u),
            None if self.modal => Ok(modal_warp(&self.gradients, u)?),
            None => Ok(u.to_vec()),
        }
    }
}

impl QuasistaticSurrogate for WarpSurrogate {
    fn name(&self) -> &str {
        self.name
    }
    fn num_dofs(&self) -> usize {
        self.rest.len()
    }
    fn propose(&mut self, input: &LoadStep<'_>) -> Result<Vec<f64>, SurrogateError> {
        let u = self.displacement(input.load)?;
        Ok(self.rest.iter().zip(&u).map(|(r, d)| r + d).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use weft_sim::guard::{GuardSettings, Outcome, QuasistaticGuard};
    use weft_sim::{Energy, Quasistatic};

    /// Modal warping of the warped solve is nearer the Neo-Hookean equilibrium than the
    /// plain linear solve under a load that bends the beam, and every proposal, guarded at
    /// the truth's tolerance, is corrected to that equilibrium.
    #[test]
    fn modal_warping_beats_the_linear_proposal_and_the_guard_corrects_every_one() {
        let mesh = weft_mesh::generators::beam(&weft_mesh::generators::BeamParams {
            cells: [4, 2, 2],
            size: [1.0, 0.5, 0.5],
        })
        .unwrap();
        let anchors: Vec<usize> = (0..mesh.num_vertices())
            .filter(|&i| mesh.positions()[i].x.abs() < 1e-9)
            .collect();
        let body = WarpSurrogateBody {
            mesh: &mesh,
            anchors: &anchors,
            young: 1e5,
            poisson: 0.3,
            warp_tolerance: 1e-6,
            warp_solves: 100,
        };
        let lame = LameParameters::from_young_poisson(1e5, 0.3).unwrap();
        let nh = TetElasticity::new(&mesh, Material::NeoHookean, lame).unwrap();
        let internal: [&dyn Energy; 1] = [&nh];
        let fixed = weft_sim::anchors::fixed_dofs(mesh.num_vertices(), &anchors).unwrap();
        let masses = weft_mesh::geometry::lumped_masses_tet(mesh.positions(), mesh.tets(), 1000.0);
        let load = weft_sim::energies::ConstantForce::directional(&masses, [0.0, -1.0, 0.0], 8.0)
            .unwrap()
            .forces()
            .to_vec();
        let mut truth = mesh.flat_positions();
        let mut solver = Quasistatic::new(truth.len(), &internal, fixed.clone()).unwrap();
        solver.solve(&internal, &load, &mut truth, 4).unwrap();
        let mut errors = Vec::new();
        for proposal in [
            WarpProposal::Linear,
            WarpProposal::WarpedLinear,
            WarpProposal::ModalWarping,
        ] {
            let mut s = WarpSurrogate::new(&body, proposal).unwrap();
            let rest = mesh.flat_positions();
            let step = LoadStep {
                step: 1,
                current: &rest,
                current_load: None,
                load: &load,
            };
            let x = s.propose(&step).unwrap();
            errors.push(x.iter().zip(&truth).map(|(a, b)| (a - b).powi(2)).sum::<f64>().sqrt());
            let solver = Quasistatic::new(truth.len(), &internal, fixed.clone()).unwrap();
            let mut guard =
                QuasistaticGuard::new(solver, &internal, 4, Box::new(s), GuardSettings::ground_truth()).unwrap();
            let mut x = rest.clone();
            let r = guard.step(&internal, 1, None, &load, &mut x, Some(&truth)).unwrap();
            assert_eq!(r.outcome, Outcome::Corrected);
            assert!(r.error.unwrap().m_rms_mm < 1e-3, "{:?}", r.error);
            assert!(r.proposal_error.unwrap().m_rms_mm > 1.0, "{:?}", r.proposal_error);
        }
        assert!(
            errors[2] < 0.9 * errors[0],
            "modal warping {} against linear {} m",
            errors[2],
            errors[0]
        );
    }
}
