"""Meshes, simulation, ACAP features and datasets from Python."""

import json
import pathlib
import re
import subprocess

import numpy as np
import pytest

import weft

REPO = pathlib.Path(__file__).resolve().parents[3]


def test_meshes_round_trip_through_files(tmp_path):
    v, f = weft.mesh.sheet(5, 0.5)
    assert v.shape == (25, 3) and f.shape == (32, 3) and f.dtype == np.int64
    v = v + np.random.default_rng(3).uniform(-0.01, 0.01, v.shape)
    for ext in ("obj", "ply", "vtk"):
        weft.mesh.write(tmp_path / f"s.{ext}", v, f)
        back = weft.mesh.read(tmp_path / f"s.{ext}")
        np.testing.assert_array_equal(back["vertices"], v)
        np.testing.assert_array_equal(back["faces"], f)
    bv, bf = weft.mesh.ball(12, 8, 0.5)
    np.testing.assert_allclose(np.linalg.norm(bv, axis=1), 0.5, atol=1e-12)
    with pytest.raises(OSError):
        weft.mesh.read(tmp_path / "missing.obj")


def test_simulate_a_built_in_scene_and_match_the_command_line(tmp_path, xtask):
    assert "sheet-ms" in weft.scene_names()
    run = weft.simulate("sheet-ms", frames=3, quick=True)
    pos = run["positions"]
    assert pos.shape[0] == 4 and pos.shape[2] == 3 and run["error"] is None
    assert run["faces"].shape[1] == 3 and np.all(np.isfinite(pos))
    # The same scene through the command line gives the same frames (its OBJ per frame).
    subprocess.run(
        [xtask, "simulate", "sheet-ms", "--quick", "--frames", "3", "--obj", "--quiet", "--out", tmp_path],
        check=True,
        capture_output=True,
    )
    frames = sorted((tmp_path / "obj").glob("frame_*.obj"))
    assert len(frames) >= 3
    last = weft.mesh.read(frames[-1])
    np.testing.assert_array_equal(last["faces"], run["faces"])
    np.testing.assert_allclose(last["vertices"], pos[-1], rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="no-such-scene"):
        weft.simulate("no-such-scene")


def test_acap_features_of_rigid_motions_decode_exactly_and_stretch_is_invariant():
    v, f = weft.mesh.sheet(6, 0.4)
    rng = np.random.default_rng(0)
    bent = v.copy()
    bent[:, 2] = 0.1 * np.sin(5 * v[:, 0]) + 0.01 * rng.standard_normal(len(v))
    acap = weft.acap.Acap(v, f)
    c, s = np.cos(0.7), np.sin(0.7)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    moved_rest = v @ rot.T + np.array([1.0, 2.0, 3.0])
    feats = acap.encode(np.stack([v, moved_rest, bent]))
    assert feats.shape == (3, len(v), 9)
    # The rest shape: no rotation; a rigid motion: the same rotation vector everywhere.
    np.testing.assert_allclose(feats[0, :, :3], 0.0, atol=1e-10)
    np.testing.assert_allclose(feats[1, :, :3], np.tile(feats[1, 0, :3], (len(v), 1)), atol=1e-10)
    np.testing.assert_allclose(feats[1, :, 3:], feats[0, :, 3:], atol=1e-10)
    # A rigid motion is reconstructed exactly from its features and one pinned vertex.
    pins = [7]
    back = acap.decode(feats[:2], pins, np.stack([v[pins], moved_rest[pins]]))
    np.testing.assert_allclose(back[0], v, atol=1e-10)
    np.testing.assert_allclose(back[1], moved_rest, atol=1e-10)
    # Moving a deformed shape rigidly leaves its stretch features unchanged.
    moved = acap.encode(bent @ rot.T + np.array([1.0, 2.0, 3.0]))
    np.testing.assert_allclose(moved[:, 3:], feats[2][:, 3:], atol=1e-8)
    with pytest.raises(ValueError):
        acap.decode(feats, [10_000], np.zeros((3, 1, 3)))


def test_load_a_dataset_with_its_checksums(tmp_path, xtask):
    out = tmp_path / "ds"
    subprocess.run(
        [xtask, "dataset", "sheet-ms", "--size", "quick", "--sequences", "1", "--quiet", "--out", out],
        check=True,
        capture_output=True,
    )
    ds = weft.datasets.load(out)
    assert ds["name"] == "sheet-ms" and len(ds["sequences"]) == 1
    seq = ds["sequences"][0]
    assert seq["positions"].ndim == 3 and seq["positions"].shape[2] == 3
    # Cloth datasets split frames inside each sequence (Tan et al.), so a sequence is "all".
    assert seq["split"] == "all" and ds["manifest"]["split"] == "frames-12-of-17"
    # A flipped byte is refused by name.
    path = out / json.loads((out / "manifest.json").read_text())["sequences"][0]["path"]
    data = bytearray(path.read_bytes())
    data[-1] ^= 1
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="SHA-256"):
        weft.datasets.load(out)


def test_the_documented_example_runs_as_written():
    text = (REPO / "docs" / "PYTHON.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    scope = {}
    exec(compile(code, "docs/PYTHON.md", "exec"), scope)
    losses = scope["losses"]
    assert losses[-1] < 0.5 * losses[0], losses
