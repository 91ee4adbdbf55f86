"""Meshes as numpy arrays: vertices float64 ``[V, 3]`` (m), faces int64 ``[F, 3]``."""

from . import _arrays, _native


def sheet(n, size=1.0):
    """A square sheet of ``n × n`` vertices and side ``size`` in the xy plane:
    ``(vertices, faces)``."""
    return _native.mesh_sheet(int(n), float(size))


def ball(segments, rings, radius=0.5):
    """A UV sphere: ``(vertices, faces)``."""
    return _native.mesh_ball(int(segments), int(rings), float(radius))


def read(path):
    """A mesh file (.obj, .ply or .vtk triangles; .node/.ele or .vtk tetrahedra) as a dict
    with ``vertices`` and ``faces`` (surfaces) or ``tets`` (volumes)."""
    return _native.mesh_read(str(path))


def write(path, vertices, faces):
    """Writes a surface by extension (.obj, .ply, .vtk) after validating it."""
    v = _arrays.positions("vertices", vertices)
    if v.ndim != 2:
        raise ValueError(f"vertices: expected shape [V, 3], got {list(v.shape)}")
    _native.mesh_write(str(path), v, _arrays.faces(faces))
