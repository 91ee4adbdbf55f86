"""The inextensibility SOCP's forward pass against cvxpy + Clarabel (docs/BENCHMARKS.md).

Case (issue: ground truth at speed): the paper-size sheet, 55 x 55 vertices (3025
vertices, 8856 edges), eps = 0.1, a prediction stretched by a smooth random factor between
1.05 and 1.30 over the sheet (random frequencies and phases per seed), a smooth 5 cm bump
and 1 mm of uniform noise. Both solve the same problem: minimise sum_i k_i |x_i - pred_i|^2
subject to |x_a - x_b| <= (1 + eps) L_e, with weft's weights k_i. Both are timed in this
process, one after the other, on every seed; weft's time is its own report's wall time of
the forward pass (conic solve, polish, checks), the peer's the wall time of
`problem.solve(solver="CLARABEL")` (cvxpy's canonicalisation included, as a user pays it)
and Clarabel's own solve time.

    python3 benches/python/socp_vs_clarabel.py [--seeds 0 1 2 3 4] [--repeats 3]

Needs the weft wheel (docs/PYTHON.md) and cvxpy with clarabel from the package registry.
"""

import argparse
import statistics
import time

import numpy as np

import weft


def case(seed):
    v, f = weft.mesh.sheet(55, 1.0)
    rng = np.random.default_rng(seed)
    fx, fy = 1.0 + 4.0 * rng.random(2)
    px, py = 2.0 * np.pi * rng.random(2)
    x, y = v[:, 0], v[:, 1]
    stretch = 1.05 + 0.25 * (0.5 + 0.5 * np.sin(fx * x + px) * np.cos(fy * y + py))
    pred = np.stack([stretch * x, stretch * y, 0.05 * np.sin(4.0 * x) * np.cos(3.0 * y)], axis=1)
    pred += 1e-3 * (rng.random(pred.shape) - 0.5)
    return v, f, pred


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--repeats", type=int, default=3, help="weft forward passes per seed (median kept)")
    args = ap.parse_args()
    import cvxpy as cp

    ratios = []
    for seed in args.seeds:
        v, f, pred = case(seed)
        layer = weft.proj.Inextensibility(v, f, 0.1)
        times = []
        for _ in range(args.repeats):
            out, state = layer.project(pred)
            times.append(state.reports[0]["time_seconds"])
        report = state.reports[0]
        ours = statistics.median(times)

        k = layer.weights
        e = layer.edges
        x = cp.Variable((len(v), 3))
        d = x[e[:, 0], :] - x[e[:, 1], :]
        problem = cp.Problem(
            cp.Minimize(cp.sum(cp.multiply(k[:, None], cp.square(x - pred)))),
            [cp.norm(d, 2, axis=1) <= (1 + layer.eps) * layer.rest_lengths],
        )
        t0 = time.perf_counter()
        problem.solve(solver="CLARABEL")
        peer = time.perf_counter() - t0
        peer_solve = problem.solver_stats.solve_time
        peer_out = x.value
        ratio = peer / ours
        ratios.append(ratio)
        print(
            f"seed {seed}: weft {1e3 * ours:.1f} ms (median of {args.repeats}; IPM {report['iterations']} iterations, "
            f"polish {report['polish_iterations']}, hand-over {report['handover_tolerance']}, "
            f"{report['active_constraints']} of {report['num_constraints']} edges at their bound) | "
            f"cvxpy + Clarabel {1e3 * peer:.0f} ms (Clarabel's solve {1e3 * peer_solve:.0f} ms, "
            f"{problem.solver_stats.num_iters} iterations) | ratio {ratio:.1f}x | "
            f"max |x_weft - x_peer| {np.abs(out - peer_out).max():.1e} m, "
            f"max violation weft {layer.max_violation(out):.1e}, peer {layer.max_violation(peer_out):.1e}"
        )
    print(f"ratio cvxpy + Clarabel / weft: median {statistics.median(ratios):.1f}x, "
          f"min {min(ratios):.1f}x over {len(ratios)} seeds")


if __name__ == "__main__":
    main()
