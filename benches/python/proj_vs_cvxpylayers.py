"""weft's inextensibility layer from Python against cvxpylayers (docs/BENCHMARKS.md).

Case (issue: weft for PyTorch users): a 32 x 32 sheet (1024 vertices, 2945 edges), eps =
0.1, a batch of 8 predictions stretched by 15 % in the plane plus 1 mm of seeded noise;
forward and backward of the loss sum(out * g) for a fixed random g. Both solve the same
problem: minimise sum_i k_i |x_i - pred_i|^2 subject to |x_a - x_b| <= (1 + eps) L_e, with
weft's weights k_i. cvxpylayers runs Clarabel (its SCS default misses the bounds by up to
0.8 %); both are timed in this process, one after the other.

Also the Python call's overhead over the Rust layer: a batch-1 forward's wall time from
Python minus the forward time weft's report measures inside Rust, same calls.

    python3 benches/python/proj_vs_cvxpylayers.py [--skip-cvxpylayers] [--repeats 5]

Needs the weft wheel (docs/PYTHON.md), torch, and for the peer cvxpylayers 1.2, cvxpy 1.9,
diffcp 1.1.9 and clarabel from the package registry.
"""

import argparse
import statistics
import time

import numpy as np
import torch

import weft
import weft.torch as wt


def case(batch=8):
    v, f = weft.mesh.sheet(32, 1.0)
    rng = np.random.default_rng(0)
    preds = np.stack([v * np.array([1.15, 1.15, 1.0]) + 1e-3 * rng.standard_normal(v.shape) for _ in range(batch)])
    g = rng.standard_normal(preds.shape)
    return v, f, preds, g


def weft_forward_backward(layer, preds, g):
    x = torch.tensor(preds, requires_grad=True)
    out = wt.inextensibility_projection(x, layer)
    (out * torch.tensor(g)).sum().backward()
    return out.detach().numpy(), x.grad.numpy()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--skip-cvxpylayers", action="store_true")
    args = ap.parse_args()
    v, f, preds, g = case()
    layer = weft.proj.Inextensibility(v, f, 0.1)
    print(f"case: {len(v)} vertices, {layer.num_constraints} edges, batch {len(preds)}, eps 0.1, 15 % stretch")

    times = []
    for _ in range(args.repeats):
        t = time.perf_counter()
        out, grad = weft_forward_backward(layer, preds, g)
        times.append(time.perf_counter() - t)
    print(f"weft forward+backward, batch 8: median {statistics.median(times):.4f} s "
          f"(min {min(times):.4f}, max {max(times):.4f}); max violation {layer.max_violation(out):.2e}")

    overhead = []
    for _ in range(args.repeats):
        t = time.perf_counter()
        _, state = layer.project(preds[0])
        overhead.append((time.perf_counter() - t) - state.reports[0]["time_seconds"])
    rust = state.reports[0]["time_seconds"]
    print(f"python overhead of a batch-1 forward: median {1e3 * statistics.median(overhead):.3f} ms "
          f"over the Rust layer's {1e3 * rust:.2f} ms")

    if args.skip_cvxpylayers:
        return
    import cvxpy as cp
    from cvxpylayers.torch import CvxpyLayer

    k = layer.weights
    e = layer.edges
    lmax = (1 + layer.eps) * layer.rest_lengths
    x = cp.Variable((len(v), 3))
    p = cp.Parameter((len(v), 3))
    d = x[e[:, 0], :] - x[e[:, 1], :]
    t0 = time.perf_counter()
    problem = cp.Problem(
        cp.Minimize(cp.sum(cp.multiply(k[:, None], cp.square(x - p)))),
        [cp.norm(d, 2, axis=1) <= lmax],
    )
    peer = CvxpyLayer(problem, parameters=[p], variables=[x])
    setup = time.perf_counter() - t0
    xp = torch.tensor(preds, requires_grad=True)
    t0 = time.perf_counter()
    (out_peer,) = peer(xp, solver_args={"solve_method": "Clarabel"})
    forward = time.perf_counter() - t0
    t0 = time.perf_counter()
    (out_peer * torch.tensor(g)).sum().backward()
    backward = time.perf_counter() - t0
    peer_out = out_peer.detach().numpy()
    print(f"cvxpylayers + Clarabel, batch 8: set-up {setup:.2f} s, forward {forward:.2f} s, backward {backward:.2f} s, "
          f"forward+backward {forward + backward:.2f} s; max violation {layer.max_violation(peer_out):.2e}")
    print(f"answers: max |x_weft - x_peer| = {np.abs(out - peer_out).max():.2e} m, "
          f"max |grad_weft - grad_peer| / max |grad| = {np.abs(grad - xp.grad.numpy()).max() / np.abs(grad).max():.2e}")
    print(f"ratio (cvxpylayers forward+backward / weft median): {(forward + backward) / statistics.median(times):.0f}x")

    # Which gradient is right: the directional derivative of L(p) = sum(out(p) * g) along a
    # seeded direction v, by central differences of weft's forward (solved to 1e-10), against
    # each method's gradient dotted with v.
    tight = weft.proj.Inextensibility(v, f, 0.1, tolerance=1e-10)
    direction = np.random.default_rng(1).standard_normal(preds.shape)
    h = 1e-6
    plus, _ = tight.project(preds + h * direction)
    minus, _ = tight.project(preds - h * direction)
    fd = float(((plus - minus) * g).sum() / (2 * h))
    ours = float((grad * direction).sum())
    theirs = float((xp.grad.numpy() * direction).sum())
    print(f"directional derivative: finite differences {fd:.6e}, weft {ours:.6e} (rel. diff {abs(ours - fd) / abs(fd):.1e}), "
          f"cvxpylayers {theirs:.6e} (rel. diff {abs(theirs - fd) / abs(fd):.1e})")


if __name__ == "__main__":
    main()
