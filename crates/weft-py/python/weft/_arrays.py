"""Input conversion shared by the wrappers: C-ordered float64/int64 arrays, shapes and
finiteness checked before anything reaches Rust."""

import numpy as np


def positions(name, a, vertices=None):
    """``a`` as a C-ordered float64 ``[..., V, 3]`` array with finite entries."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    if a.ndim < 2 or a.shape[-1] != 3:
        raise ValueError(f"{name}: expected shape [..., V, 3], got {list(a.shape)}")
    if vertices is not None and a.shape[-2] != vertices:
        raise ValueError(f"{name}: expected {vertices} vertices, got shape {list(a.shape)}")
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0].tolist()
        raise ValueError(f"{name}: non-finite value at index {bad}")
    return a


def faces(f):
    f = np.ascontiguousarray(f, dtype=np.int64)
    if f.ndim != 2 or f.shape[1] != 3:
        raise ValueError(f"faces: expected shape [F, 3], got {list(f.shape)}")
    return f


def batched(name, a, vertices):
    """``a`` as ``[B, V, 3]`` and whether it came without a batch dimension."""
    a = positions(name, a, vertices)
    if a.ndim == 2:
        return a[None], True
    if a.ndim != 3:
        raise ValueError(f"{name}: expected shape [V, 3] or [B, V, 3], got {list(a.shape)}")
    return a, False


def keys(k, batch):
    if k is None:
        return None
    k = [int(x) for x in np.asarray(k).reshape(-1)]
    if len(k) != batch:
        raise ValueError(f"keys: one per example expected ({batch}), got {len(k)}")
    return k
