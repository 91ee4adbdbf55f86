"""Scenes simulated into numpy arrays, alone or with a learned surrogate under the guard."""

import os

from . import _native


def scene_names():
    """The built-in scenes' names."""
    return _native.scene_names()


def simulate(scene, frames=None, quick=False, allow_partial=False, surrogate=None, tolerance=None, certified=False):
    """Runs ``scene`` — a built-in name (``weft.scene_names()``) or a scene TOML file — for
    ``frames`` frames (the scene's own count by default; ``quick`` picks its small
    variant). Returns a dict: ``name``, ``positions`` ``[F + 1, V, 3]`` in metres (frame 0
    is the initial state), every other recorded array by name, ``faces`` (or ``tets`` for
    volume scenes) and ``seconds``.

    A run that stops early raises ``weft.SolverError`` whose ``report`` holds the reason
    and the frames simulated before it (``report["result"]``), unless ``allow_partial``,
    which returns them with ``result["error"]`` set.

    **Guarded** (docs/GUARD.md): with ``surrogate``, a model directory
    (``weft.train_inertial_correction`` or ``cargo xtask train inertial-correction``), the
    surrogate proposes every frame of a cloth scene and the guard accepts a proposal whose
    error estimate is within ``tolerance`` — millimetres (mass-weighted RMS per
    coordinate) or ``"truth"`` (the ground truth's own convergence test, the default) —
    and corrects it by Newton from the proposal otherwise; ``certified`` accepts on the
    certified bound only. The dict then holds ``name``, ``positions``, ``faces``,
    ``seconds`` and ``guard``, what ``cargo xtask simulate SCENE --surrogate M`` writes to
    ``guard.json``: ``settings``, ``totals`` (``frames``, ``accepted``, ``corrected``,
    ``rejected``, ``unverified``, ``newton_iterations``, ``factorizations``) and
    ``per_frame`` (each frame's ``outcome``, ``estimate``, ``proposal_estimate``,
    ``newton_iterations``, ``factorizations`` and ``seconds`` split into ``proposal``,
    ``guard`` and ``correction``).

    A tolerance that is not a positive, finite number of millimetres or ``"truth"``, a
    model of another kind, and a surrogate fitted on another scene, mesh or time step raise
    ``ValueError``; a missing model directory ``OSError``; a correction that does not
    converge ``weft.SolverError``.
    """
    if tolerance is not None and not isinstance(tolerance, str):
        tolerance = repr(float(tolerance))
    result = _native.simulate(
        str(scene),
        None if frames is None else int(frames),
        bool(quick),
        None if surrogate is None else os.fspath(surrogate),
        tolerance,
        bool(certified),
    )
    if result["error"] is not None and not allow_partial:
        done = result["positions"].shape[0] - 1
        raise _native.SolverError(
            f"{result['name']}: stopped after {done} frame(s): {result['error']}",
            {"kind": "simulation", "frames": done, "result": result},
        )
    return result


def train_inertial_correction(data, out, config=None):
    """Fits the inertial correction — the one-step surrogate the guard steps (docs/GUARD.md,
    "A surrogate to guard") — on the cloth dataset in ``data`` (``cargo xtask dataset``)
    and writes the model directory ``out``, which must not hold a model yet; settings from
    the JSON file ``config``, else the defaults. Returns the lines ``cargo xtask train
    inertial-correction`` prints: the chosen ridge weight and the validation and test
    one-step errors beside the inertial predictor's.
    """
    return _native.train_inertial_correction(
        os.fspath(data), os.fspath(out), None if config is None else os.fspath(config)
    )
