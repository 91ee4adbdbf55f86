"""weft datasets (``cargo xtask dataset``) as numpy arrays."""

from . import _native


def load(path):
    """The dataset in directory ``path``, every file checked against its manifest's
    SHA-256 first: a dict with ``name``, ``manifest`` and ``sequences`` — each a dict with
    ``index``, ``split`` (train, validation or test; ``all`` where the dataset splits the
    frames inside each sequence, as the cloth datasets do), ``metadata`` and its arrays by name
    (e.g. ``positions`` ``[F, V, 3]`` in metres for cloth). A changed or missing file
    raises ``ValueError`` or ``OSError`` naming it."""
    return _native.load_dataset(str(path))
