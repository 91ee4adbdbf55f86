"""weft: fast, physically faithful deformable simulation, from Python.

The numerics are weft's Rust crates (``weft._native``); this package converts arrays and
raises typed exceptions:

- ``weft.proj``: Geng et al.'s inextensibility and quasistatic projection layers on numpy
  batches, with their vector-Jacobian products (for JAX or any framework);
- ``weft.torch``: the same layers as ``torch.nn.Module``s over autograd functions;
- ``weft.mesh``: built-in meshes and mesh files;
- ``weft.simulate``: a built-in scene or a scene TOML file, frames as arrays; with a
  surrogate (``weft.train_inertial_correction``) and a tolerance, under the guard;
- ``weft.acap``: ACAP deformation features and their Poisson inverse;
- ``weft.datasets``: a weft dataset (manifest checksums verified) as arrays.

Units: metres, seconds, newtons; positions are float64 ``[V, 3]`` or ``[B, V, 3]``.
Bad input raises ``ValueError`` (``OSError`` for files); a solve that does not reach its
answer raises ``weft.SolverError``, whose ``report`` holds what the solver reported.
"""

from . import _native

__version__ = _native.__version__

SolverError = _native.SolverError


def _report(self):
    """The solver's report (a dict), or None."""
    return self.args[1] if len(self.args) > 1 else None


SolverError.report = property(_report)

from . import acap, datasets, mesh, proj  # noqa: E402
from .sim import scene_names, simulate, train_inertial_correction  # noqa: E402

__all__ = [
    "SolverError",
    "acap",
    "datasets",
    "mesh",
    "proj",
    "scene_names",
    "simulate",
    "train_inertial_correction",
]
