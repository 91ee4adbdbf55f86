//! The SOCP forward solve by Clarabel on the full conic KKT system, kept to cross-check
//! weft's reduced interior-point method.

use super::*;

impl InextensibilityLayer {
    /// Solves the SOCP for `b` with Clarabel. A fresh solver per call keeps results
    /// independent of call order and thread.
    pub(super) fn solve_clarabel(&self, b: &[f64]) -> Result<ConicSolution> {
        let tol = self.settings.tolerance;
        let settings = DefaultSettings {
            verbose: self.settings.verbose,
            iterative_refinement_enable: self.settings.iterative_refinement,
            max_iter: self.settings.max_iterations,
            tol_gap_abs: tol,
            tol_gap_rel: tol,
            tol_feas: tol,
            tol_ktratio: tol.min(1e-6),
            ..DefaultSettings::default()
        };
        let q = vec![0.0; 3 * self.num_vertices()];
        let mut solver = DefaultSolver::new(&self.p, &q, &self.a, b, &self.cones, settings)
            .map_err(|e| Error::SolverSetup(e.to_string()))?;
        solver.solve();
        let sol = &solver.solution;
        let status = format!("{:?}", sol.status);
        if !matches!(sol.status, SolverStatus::Solved | SolverStatus::AlmostSolved) {
            return Err(Error::SolverFailed {
                status,
                iterations: sol.iterations,
            });
        }
        Ok(ConicSolution {
            x: sol.x.clone(),
            s: sol.s.clone(),
            z: sol.z.clone(),
            status,
            iterations: sol.iterations,
            seconds: sol.solve_time,
            primal_residual: sol.r_prim,
            dual_residual: sol.r_dual,
        })
    }
}
