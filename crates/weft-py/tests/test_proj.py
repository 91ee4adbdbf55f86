"""The projection layers from Python: gradients against finite differences, agreement
with the Rust command line, batching, warm starts and typed errors."""

import subprocess

import numpy as np
import pytest
import torch

import weft
import weft.torch as wt


def stretched_sheet(n=4, seed=0, stretch=1.3):
    v, f = weft.mesh.sheet(n, 0.3)
    rng = np.random.default_rng(seed)
    pred = v * np.array([stretch, 1.0, 1.0]) + 0.01 * rng.standard_normal(v.shape)
    return v, f, pred


def test_inextensibility_gradient_matches_finite_differences():
    v, f, pred = stretched_sheet()
    layer = weft.proj.Inextensibility(v, f, 0.1, tolerance=1e-10)
    x = torch.tensor(pred[None], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda p: wt.inextensibility_projection(p, layer), (x,), eps=1e-6, atol=1e-6)
    out, state = layer.project(pred)
    assert max(r["max_violation"] for r in state.reports) <= 1e-6
    # The problem as exposed: every edge constrained, the bound recomputed from arrays.
    assert layer.edges.shape == (layer.num_constraints, 2) and layer.weights.shape == (len(v),)
    assert layer.max_violation(out) <= 1e-6 < layer.max_violation(pred)
    np.testing.assert_allclose(layer.weights.mean(), 1.0, rtol=1e-12)
    # Something was projected: the prediction broke the bound.
    assert np.abs(out - pred).max() > 1e-3


@pytest.mark.parametrize("learn", ["global", "per-vertex"])
def test_quasistatic_gradients_match_finite_differences(learn):
    v, f, pred = stretched_sheet(seed=1, stretch=1.2)
    layer = weft.proj.Quasistatic(v, f, tolerance=1e-12)
    x = torch.tensor(pred[None], dtype=torch.float64, requires_grad=True)
    if learn == "global":
        mu = torch.tensor(0.5, dtype=torch.float64, requires_grad=True)
    else:
        rng = np.random.default_rng(2)
        mu = torch.tensor(rng.uniform(0.3, 1.0, len(v)), requires_grad=True)
    assert torch.autograd.gradcheck(
        lambda p, m: wt.quasistatic_projection(p, m, layer), (x, mu), eps=1e-6, atol=1e-6
    )


def write_obj(path, v, f):
    weft.mesh.write(path, v, f)


def test_forward_equals_the_command_line(tmp_path, xtask):
    v, f, pred = stretched_sheet(n=6, seed=3)
    write_obj(tmp_path / "rest.obj", v, f)
    write_obj(tmp_path / "pred.obj", pred, f)
    for cmd, layer, kwargs in [
        (["socp", "--eps", "0.1"], weft.proj.Inextensibility(v, f, 0.1), {}),
        (["quasistatic", "--mu", "0.1"], weft.proj.Quasistatic(v, f), {"mu": 0.1}),
    ]:
        out_path = tmp_path / f"{cmd[0]}.obj"
        subprocess.run(
            [xtask, "project", *cmd, "--rest", tmp_path / "rest.obj", "--pred", tmp_path / "pred.obj", "--out", out_path],
            check=True,
            capture_output=True,
        )
        cli = weft.mesh.read(out_path)["vertices"]
        # The OBJ round trip is exact (shortest round-trip decimal form).
        pred_back = weft.mesh.read(tmp_path / "pred.obj")["vertices"]
        ours, _ = layer.project(pred_back, **kwargs)
        np.testing.assert_allclose(ours, cli, rtol=0, atol=1e-12, err_msg=cmd[0])


def test_a_batch_of_one_equals_the_unbatched_call_and_dtypes_are_kept():
    v, f, pred = stretched_sheet(seed=4)
    layer = wt.InextensibilityProjection(v, f, 0.1)
    single = layer(torch.tensor(pred))
    batch = layer(torch.tensor(pred[None]))
    assert single.shape == (len(v), 3) and batch.shape == (1, len(v), 3)
    assert torch.equal(single, batch[0])
    f32 = layer(torch.tensor(pred[None], dtype=torch.float32))
    assert f32.dtype == torch.float32
    assert torch.allclose(f32.double(), batch, atol=1e-5)
    qs = wt.QuasistaticProjection(v, f, mu=0.5)
    assert torch.equal(qs(torch.tensor(pred)), qs(torch.tensor(pred[None]))[0])


def test_warm_starts_are_keyed_per_example_and_give_the_same_answer():
    v, f, pred = stretched_sheet(seed=5)
    layer = weft.proj.Inextensibility(v, f, 0.1)
    batch = np.stack([pred, pred * 1.05])
    cold, _ = layer.project(batch)
    layer.project(batch, keys=[10, 11])
    assert layer.warm_keys() == [10, 11]
    warm, state = layer.project(batch * 1.001, keys=[10, 11])
    again, _ = layer.project(batch * 1.001)
    np.testing.assert_allclose(warm, again, atol=1e-8)
    assert len(state.reports) == 2
    with pytest.raises(ValueError, match="keys"):
        layer.project(batch, keys=[1])
    with pytest.raises(ValueError, match="twice"):
        layer.project(batch, keys=[1, 1])


def test_bad_input_raises_typed_errors_and_a_failed_batch_remembers_nothing(tmp_path):
    v, f, pred = stretched_sheet(seed=6)
    layer = weft.proj.Quasistatic(v, f)
    with pytest.raises(ValueError, match="vertices"):
        layer.project(pred[:-1])
    nan = pred.copy()
    nan[3, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        layer.project(nan)
    with pytest.raises(ValueError, match="mu"):
        layer.project(pred, mu=-1.0)
    with pytest.raises(ValueError, match="mu"):
        layer.project(pred, mu=np.ones(3))
    with pytest.raises(ValueError, match="faces"):
        weft.proj.Inextensibility(v, f[:, :2], 0.1)
    with pytest.raises(ValueError):
        weft.proj.Inextensibility(v, f + len(v), 0.1)
    # A prediction collapsed to one point has no minimum to project onto: the second
    # example fails inside the solver, and the first example's solution is not kept.
    collapsed = np.zeros_like(pred)
    with pytest.raises(weft.SolverError) as err:
        layer.project(np.stack([pred, collapsed]), mu=1e-3, keys=[0, 1])
    assert "example 1" in str(err.value)
    assert isinstance(err.value.report, dict) and "kind" in err.value.report
    assert layer.warm_keys() == []
    # A rejected mesh is not written.
    with pytest.raises(ValueError):
        weft.mesh.write(tmp_path / "bad.obj", v, f + len(v))
    assert not (tmp_path / "bad.obj").exists()
    with pytest.raises(ValueError, match="learn_mu"):
        wt.QuasistaticProjection(v, f, learn_mu="sometimes")
    with pytest.raises(ValueError, match="positive"):
        wt.QuasistaticProjection(v, f, mu=0.0)


def test_a_few_training_steps_through_the_quasistatic_layer_lower_the_loss():
    torch.manual_seed(0)
    v, f = weft.mesh.sheet(6, 0.3)
    layer = wt.QuasistaticProjection(v, f, mu=1.0, learn_mu="per-vertex")
    rest = torch.from_numpy(v)
    code = torch.linspace(0.0, 1.0, 3, dtype=torch.float64)[:, None]
    target = rest.expand(3, -1, -1).clone()
    target[..., 2] = 0.05 * code * torch.sin(8 * rest[:, 0])
    net = torch.nn.Sequential(torch.nn.Linear(1, 32), torch.nn.Tanh(), torch.nn.Linear(32, rest.numel())).double()
    opt = torch.optim.Adam([*net.parameters(), *layer.parameters()], lr=1e-2)
    losses = []
    for _ in range(8):
        out = layer(rest + net(code).view(3, -1, 3), keys=[0, 1, 2])
        loss = ((out - target) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.5 * losses[0], losses
    assert layer.log_mu.grad is not None and torch.all(torch.isfinite(layer.log_mu.grad))
