import os
import pathlib

import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def xtask():
    """The weft command-line binary (built by the workspace's tests; WEFT_XTASK overrides)."""
    path = pathlib.Path(os.environ.get("WEFT_XTASK", REPO / "target" / "release" / "xtask"))
    assert path.exists(), f"{path} is missing: build it with `cargo build --release -p xtask`"
    return path
