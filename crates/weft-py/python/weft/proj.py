"""Geng et al.'s projection layers on numpy (``weft.torch`` wraps them for PyTorch).

``Inextensibility(rest_vertices, faces, eps)`` maps predictions ``[B, V, 3]`` (or ``[V, 3]``)
to the mass-weighted closest configurations whose edges are at most ``(1 + eps)`` times
their rest length (a second-order cone program, solved to 1e-8 and polished on its active
set); ``Quasistatic(rest_vertices, faces, ...)`` to the equilibria of edge, bending and
axial springs tied to the prediction by zero-length springs of scale ``mu`` (a float, or
one per vertex). Each ``project`` returns the positions and a state; ``vjp(state, grad)``
is the vector-Jacobian product from weft's hand-written backward pass. ``keys`` names
the examples: each solve then starts from that example's previous solution (training
revisits examples), and a batch that fails remembers nothing.

``socp(rest_vertices, faces, predictions, eps)`` and ``quasistatic(...)`` are one-call
forms that build the layer each time.
"""

import numpy as np

from . import _arrays, _native


class Inextensibility:
    def __init__(self, rest_vertices, faces, eps, tolerance=1e-8, max_iterations=100):
        rest = _arrays.positions("rest_vertices", rest_vertices)
        if rest.ndim != 2:
            raise ValueError(f"rest_vertices: expected shape [V, 3], got {list(rest.shape)}")
        self.native = _native.Inextensibility(
            rest, _arrays.faces(faces), float(eps), float(tolerance), int(max_iterations)
        )
        self.num_vertices = self.native.num_vertices
        self.num_constraints = self.native.num_constraints
        self.eps = self.native.eps
        #: Objective weights k_i: the projection minimises sum_i k_i |x_i - pred_i|^2.
        self.weights = self.native.weights
        #: Edges [E, 2] and rest lengths [E]: edge e is kept at most (1 + eps) rest_lengths[e].
        self.edges = self.native.edges
        self.rest_lengths = self.native.rest_lengths

    def max_violation(self, positions):
        """max_e (l_e / ((1 + eps) L_e) - 1) of ``[V, 3]`` or ``[B, V, 3]`` positions (<= 0
        when every bound holds)."""
        x = np.asarray(positions, dtype=np.float64)
        d = x[..., self.edges[:, 0], :] - x[..., self.edges[:, 1], :]
        return float((np.linalg.norm(d, axis=-1) / ((1 + self.eps) * self.rest_lengths) - 1).max())

    def project(self, predictions, keys=None):
        """``(positions, state)``; ``state.reports`` lists each example's solver report."""
        x, single = _arrays.batched("predictions", predictions, self.num_vertices)
        out, native_state, reports = self.native.forward(x, _arrays.keys(keys, x.shape[0]))
        return (out[0] if single else out), _State(native_state, reports, single)

    def vjp(self, state, grad_output):
        """``∂E/∂predictions`` from ``∂E/∂positions`` (same shape as ``project``'s output)."""
        g, _ = _arrays.batched("grad_output", grad_output, self.num_vertices)
        out = self.native.backward(state.native, g)
        return out[0] if state.single else out

    def warm_keys(self):
        """The example keys with a remembered solution."""
        return self.native.warm_keys()

    def clear_warm_starts(self):
        self.native.clear_warm_starts()


class Quasistatic:
    def __init__(
        self,
        rest_vertices,
        faces,
        stretch_stiffness=1.0,
        bend_stiffness=0.1,
        axial_stiffness=0.1,
        zero_length_stiffness=1.0,
        tolerance=1e-8,
        max_iterations=100,
    ):
        rest = _arrays.positions("rest_vertices", rest_vertices)
        if rest.ndim != 2:
            raise ValueError(f"rest_vertices: expected shape [V, 3], got {list(rest.shape)}")
        self.native = _native.Quasistatic(
            rest,
            _arrays.faces(faces),
            float(stretch_stiffness),
            float(bend_stiffness),
            float(axial_stiffness),
            float(zero_length_stiffness),
            float(tolerance),
            int(max_iterations),
        )
        self.num_vertices = self.native.num_vertices

    def _mu(self, mu):
        if np.ndim(mu) == 0:
            return float(mu)
        m = np.ascontiguousarray(mu, dtype=np.float64).reshape(-1)
        if m.shape[0] != self.num_vertices:
            raise ValueError(f"mu: expected a float or shape [{self.num_vertices}], got {list(np.shape(mu))}")
        return m

    def project(self, predictions, mu=1.0, keys=None):
        """``(positions, state)``; ``state.reports`` lists each example's Newton report."""
        x, single = _arrays.batched("predictions", predictions, self.num_vertices)
        out, native_state, reports = self.native.forward(x, self._mu(mu), _arrays.keys(keys, x.shape[0]))
        return (out[0] if single else out), _State(native_state, reports, single)

    def vjp(self, state, grad_output):
        """``(∂E/∂predictions, ∂E/∂mu_i)``: the second is ``[B, V]`` (``[V]`` unbatched);
        a global mu's gradient is its sum over vertices."""
        g, _ = _arrays.batched("grad_output", grad_output, self.num_vertices)
        d_pred, d_mu = self.native.backward(state.native, g)
        return (d_pred[0], d_mu[0]) if state.single else (d_pred, d_mu)

    def warm_keys(self):
        """The example keys with a remembered solution."""
        return self.native.warm_keys()

    def clear_warm_starts(self):
        self.native.clear_warm_starts()


class _State:
    """What a ``vjp`` needs of its ``project`` call (the solutions, kept in Rust)."""

    def __init__(self, native, reports, single):
        self.native = native
        self.reports = reports
        self.single = single


def socp(rest_vertices, faces, predictions, eps, **settings):
    """One-call inextensibility projection: ``(positions, layer, state)``."""
    layer = Inextensibility(rest_vertices, faces, eps, **settings)
    out, state = layer.project(predictions)
    return out, layer, state


def quasistatic(rest_vertices, faces, predictions, mu=1.0, **params):
    """One-call quasistatic projection: ``(positions, layer, state)``."""
    layer = Quasistatic(rest_vertices, faces, **params)
    out, state = layer.project(predictions, mu)
    return out, layer, state
