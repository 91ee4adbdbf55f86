//! The backward pass: implicit differentiation of the conic KKT system at the solution
//! (Geng et al. Eq. 6–11), one regularised LDLᵀ solve over the active edges.

use super::polish::covers;
use super::*;

impl InextensibilityLayer {
    /// `∂E/∂r̂` from `∂E/∂r*` (`grad_out`) at a forward solution (Geng et al. Eq. 11).
    pub fn backward(&self, solution: &SocpSolution, grad_out: &[f64]) -> Result<Vec<f64>> {
        self.backward_with_report(solution, grad_out).map(|(g, _)| g)
    }

    /// [`backward`](Self::backward) with a report of the linear solve.
    pub fn backward_with_report(
        &self,
        solution: &SocpSolution,
        grad_out: &[f64],
    ) -> Result<(Vec<f64>, BackwardReport)> {
        let start = Instant::now();
        self.rest.check_positions("output gradient", grad_out)?;
        let n = 3 * self.num_vertices();
        let m = self.num_constraints();
        if solution.s.len() != 4 * m || solution.z.len() != 4 * m || solution.positions.len() != n {
            return Err(Error::LengthMismatch {
                what: "forward state",
                expected: 4 * m,
                got: solution.s.len(),
            });
        }
        // Edges carrying force (Appendix A, last paragraph: the others decouple). After
        // the polish they are its active edges, whose system (and symbolic factor) the
        // solution carries.
        let (s_all, z_all) = (&solution.s, &solution.z);
        let loaded: Vec<bool> = (0..m).map(|e| z_all[4 * e] > 0.0 && s_all[4 * e] > 0.0).collect();
        let system = match &solution.active_system {
            Some(system) if covers(system, &loaded) => system.clone(),
            _ => self.system_over(&loaded)?,
        };
        let mut rows = 0;
        let blocks: Vec<EdgeBlock> = system
            .ids()
            .iter()
            .map(|&e| {
                let (s, z) = (&s_all[4 * e..4 * e + 4], &z_all[4 * e..4 * e + 4]);
                let (s0, z0) = (s[0], z[0]);
                if !loaded[e] {
                    return EdgeBlock::decoupled();
                }
                let s1 = nalgebra::Vector3::new(s[1], s[2], s[3]);
                let s1n = s1.norm();
                // γ = (s⁰² − ‖s¹‖²)/s⁰ without cancellation; ≥ 0 inside the cone.
                let gamma = ((s0 - s1n) * (s0 + s1n) / s0).max(0.0);
                let v = s1 / s0;
                let primal = nalgebra::Matrix3::identity() * (z0 / s0);
                if Self::is_active(s, z) {
                    rows += 1;
                    EdgeBlock {
                        primal,
                        coupling: Some(v),
                        diagonal: -gamma / (2.0 * z0),
                    }
                } else {
                    // Exact elimination of the nearly decoupled row (its Schur complement).
                    EdgeBlock {
                        primal: primal + v * v.transpose() * (2.0 * z0 / gamma),
                        ..EdgeBlock::decoupled()
                    }
                }
            })
            .collect();
        let factor = self.factorize_kkt(&system, blocks)?;
        let mut rhs = vec![0.0; n + system.ids().len()];
        rhs[..n].copy_from_slice(grad_out);
        let linear_residual = factor.solve_in_place(&mut rhs);
        let w = self.rest.weights();
        let grad_in: Vec<f64> = (0..n).map(|i| w[i / 3] * rhs[i]).collect();
        check_output("SOCP backward gradient", &grad_in)?;
        let report = BackwardReport {
            time_seconds: start.elapsed().as_secs_f64(),
            linear_residual,
            constraint_rows: rows,
        };
        Ok((grad_in, report))
    }
}
