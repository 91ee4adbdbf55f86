"""Scenes simulated into numpy arrays."""

from . import _native


def scene_names():
    """The built-in scenes' names."""
    return _native.scene_names()


def simulate(scene, frames=None, quick=False, allow_partial=False):
    """Runs ``scene`` — a built-in name (``weft.scene_names()``) or a scene TOML file — for
    ``frames`` frames (the scene's own count by default; ``quick`` picks its small
    variant). Returns a dict: ``name``, ``positions`` ``[F + 1, V, 3]`` in metres (frame 0
    is the initial state), every other recorded array by name, ``faces`` (or ``tets`` for
    volume scenes) and ``seconds``.

    A run that stops early raises ``weft.SolverError`` whose ``report`` holds the reason
    and the frames simulated before it (``report["result"]``), unless ``allow_partial``,
    which returns them with ``result["error"]`` set.
    """
    result = _native.simulate(str(scene), None if frames is None else int(frames), bool(quick))
    if result["error"] is not None and not allow_partial:
        done = result["positions"].shape[0] - 1
        raise _native.SolverError(
            f"{result['name']}: stopped after {done} frame(s): {result['error']}",
            {"kind": "simulation", "frames": done, "result": result},
        )
    return result
