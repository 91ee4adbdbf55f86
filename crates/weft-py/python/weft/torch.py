"""Geng et al.'s projection layers as PyTorch modules (CPU; float32 or float64).

``InextensibilityProjection(rest_vertices, faces, eps)`` and
``QuasistaticProjection(rest_vertices, faces, mu=..., learn_mu=None | "global" |
"per-vertex")`` take predictions ``[B, V, 3]`` (or ``[V, 3]``) and return projected
positions of the same shape and dtype. Their gradients — with respect to the prediction,
and to mu when it is learned — come from weft's hand-written backward passes (the conic
optimality conditions of the SOCP, one adjoint solve of the quasistatic equilibrium), not
from unrolling a solver. The solves run in float64 in Rust, one example per thread.

Pass ``keys`` (one integer per example, e.g. dataset indices) to warm-start each example
from its previous solution, as training revisits the same examples every epoch.
"""

import numpy as np
import torch

from . import proj as _proj


def _numpy64(t):
    return t.detach().to(device="cpu", dtype=torch.float64).contiguous().numpy()


class _InextensibilityFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, predictions, layer, keys):
        out, state = layer.project(_numpy64(predictions), keys)
        ctx.layer, ctx.state = layer, state
        return torch.from_numpy(np.ascontiguousarray(out)).to(predictions.dtype)

    @staticmethod
    def backward(ctx, grad_output):
        g = ctx.layer.vjp(ctx.state, _numpy64(grad_output))
        return torch.from_numpy(np.ascontiguousarray(g)).to(grad_output.dtype), None, None


class _QuasistaticFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, predictions, mu, layer, keys):
        m = _numpy64(mu)
        out, state = layer.project(_numpy64(predictions), float(m) if m.ndim == 0 else m, keys)
        ctx.layer, ctx.state, ctx.mu_shape = layer, state, mu.shape
        ctx.dtypes = (predictions.dtype, mu.dtype)
        return torch.from_numpy(np.ascontiguousarray(out)).to(predictions.dtype)

    @staticmethod
    def backward(ctx, grad_output):
        d_pred, d_mu = ctx.layer.vjp(ctx.state, _numpy64(grad_output))
        grad_pred = torch.from_numpy(np.ascontiguousarray(d_pred)).to(ctx.dtypes[0])
        grad_mu = None
        if ctx.needs_input_grad[1]:
            # Per-vertex gradients [B, V] ([V] unbatched) summed over the batch; a global
            # mu's is their sum over the vertices too.
            per_vertex = np.asarray(d_mu)
            if per_vertex.ndim == 2:
                per_vertex = per_vertex.sum(axis=0)
            g = per_vertex.sum() if len(ctx.mu_shape) == 0 else per_vertex
            grad_mu = torch.as_tensor(g, dtype=torch.float64).to(ctx.dtypes[1]).reshape(ctx.mu_shape)
        return grad_pred, grad_mu, None, None


def inextensibility_projection(predictions, layer, keys=None):
    """The differentiable projection of ``predictions`` by a ``weft.proj.Inextensibility``."""
    return _InextensibilityFunction.apply(predictions, layer, keys)


def quasistatic_projection(predictions, mu, layer, keys=None):
    """The differentiable projection of ``predictions`` by a ``weft.proj.Quasistatic`` under
    ``mu`` (a scalar tensor or one per vertex), differentiable in both."""
    return _QuasistaticFunction.apply(predictions, mu, layer, keys)


class InextensibilityProjection(torch.nn.Module):
    """Projects onto edge lengths at most ``(1 + eps)`` times the rest lengths."""

    def __init__(self, rest_vertices, faces, eps, tolerance=1e-8, max_iterations=100):
        super().__init__()
        self.layer = _proj.Inextensibility(rest_vertices, faces, eps, tolerance, max_iterations)

    def forward(self, predictions, keys=None):
        return inextensibility_projection(predictions, self.layer, keys)


class QuasistaticProjection(torch.nn.Module):
    """The quasistatic spring equilibrium tied to the prediction with scale ``mu``.

    ``learn_mu``: ``None`` keeps ``mu`` fixed, ``"global"`` learns one scalar,
    ``"per-vertex"`` one value per vertex (Geng et al. §6.2). A learned mu is stored as
    its logarithm (``self.log_mu``), so no optimiser step can make it non-positive;
    ``self.mu`` is its current value either way.
    """

    def __init__(self, rest_vertices, faces, mu=1.0, learn_mu=None, **params):
        super().__init__()
        self.layer = _proj.Quasistatic(rest_vertices, faces, **params)
        v = self.layer.num_vertices
        init = torch.as_tensor(mu, dtype=torch.float64)
        if init.ndim not in (0, 1) or (init.ndim == 1 and init.shape[0] != v):
            raise ValueError(f"mu: expected a scalar or shape [{v}], got {list(init.shape)}")
        if not bool(torch.all(torch.isfinite(init) & (init > 0))):
            raise ValueError("mu: every value must be positive and finite")
        self.learn_mu = learn_mu
        if learn_mu is None:
            self.register_buffer("fixed_mu", init.clone())
        elif learn_mu == "global":
            if init.ndim != 0:
                raise ValueError('mu: learn_mu="global" needs a scalar mu')
            self.log_mu = torch.nn.Parameter(init.log())
        elif learn_mu == "per-vertex":
            self.log_mu = torch.nn.Parameter((init.expand(v) if init.ndim == 0 else init).log().clone())
        else:
            raise ValueError(f'learn_mu: None, "global" or "per-vertex", got {learn_mu!r}')

    @property
    def mu(self):
        return self.fixed_mu if self.learn_mu is None else self.log_mu.exp()

    def forward(self, predictions, keys=None):
        return quasistatic_projection(predictions, self.mu, self.layer, keys)
