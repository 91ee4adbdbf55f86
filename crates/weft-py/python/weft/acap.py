"""ACAP deformation features (Gao et al.; Tan et al. §III) and their Poisson inverse.

``Acap(rest_vertices, faces)`` holds one rest mesh; ``encode(frames)`` gives 9 numbers per
vertex and frame (log-rotation, then the symmetric stretch's six entries) and
``decode(features, pins, pin_positions)`` rebuilds positions with the ``pins`` held.
"""

import numpy as np

from . import _arrays, _native


class Acap:
    def __init__(self, rest_vertices, faces):
        rest = _arrays.positions("rest_vertices", rest_vertices)
        if rest.ndim != 2:
            raise ValueError(f"rest_vertices: expected shape [V, 3], got {list(rest.shape)}")
        self.native = _native.Acap(rest, _arrays.faces(faces))
        self.num_vertices = self.native.num_vertices

    def encode(self, frames, sequence=False):
        """Features ``[F, V, 9]`` of ``[F, V, 3]`` frames (``[V, 9]`` for one ``[V, 3]``)."""
        x, single = _arrays.batched("frames", frames, self.num_vertices)
        out = self.native.encode(x, bool(sequence))
        return out[0] if single else out

    def decode(self, features, pins, pin_positions):
        """Positions ``[F, V, 3]`` from features ``[F, V, 9]``, vertices ``pins`` held at
        ``pin_positions`` ``[F, P, 3]`` (one frame: ``[V, 9]`` and ``[P, 3]``)."""
        f = np.ascontiguousarray(features, dtype=np.float64)
        single = f.ndim == 2
        if single:
            f = f[None]
        if not np.all(np.isfinite(f)):
            raise ValueError("features: non-finite value")
        pins = [int(p) for p in np.asarray(pins).reshape(-1)]
        p = _arrays.positions("pin_positions", pin_positions, len(pins))
        if single:
            p = p[None] if p.ndim == 2 else p
        out = self.native.decode(f, pins, p)
        return out[0] if single else out


def encode(rest_vertices, faces, frames, sequence=False):
    return Acap(rest_vertices, faces).encode(frames, sequence)


def decode(rest_vertices, faces, features, pins, pin_positions):
    return Acap(rest_vertices, faces).decode(features, pins, pin_positions)
