"""Tests of ``training/untangler.py``, ``training/untangler_data.py`` and ``export/untangler.py`` on a
tiny network (a few seconds): explicit Jacobian vs autograd, deterministic resumable training, and
the ONNX export round trip with its check."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from export import untangler as export_untangler  # noqa: E402
from export.untangler import export, load_exported, reexport_row  # noqa: E402
from service.pipeline.untangle import untangle  # noqa: E402
from service.pipeline.untangle_onnx import CONFIG_FILE, EXPORT_TOLERANCE, PAD_F, PAD_H, NeuralUntangler  # noqa: E402
from training.untangler import UntanglerConfig, UntanglerNet, evaluate, train  # noqa: E402
from training.untangler_data import sample_batch, sample_layered  # noqa: E402

TINY = UntanglerConfig(hidden=16, depth=2, steps=80, batch=512, log_every=40, checkpoint_every=10)


@pytest.fixture(autouse=True)
def _one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def tiny_net() -> UntanglerNet:
    return train(TINY, None, log=lambda _: None).net


def silent(_):
    pass


def test_samples():
    rng = np.random.default_rng(0)
    f, h = sample_layered(rng, 20_000)
    gaps = f[:, :-1] - f[:, 1:]
    assert np.median(np.abs(gaps[:, 1:])) < 0.02 and np.mean(gaps < 0) > 0.1  # mm apart, some crossing
    f, h, used = sample_batch(rng, 20_000, padded=0.3)
    assert np.all(h[:, 0] == -1.0) and np.all(used[:, 0])
    assert np.all(f[~used] == PAD_F) and np.all(h[~used] == PAD_H)
    assert 0.1 < np.mean(~used.all(axis=1)) < 0.3


def _jacobian_case(head: str, activation: str, rng: np.random.Generator):
    """(a float64 net whose every term matters, f*, h* (64, 5) with half the points in the blend band)."""
    torch.manual_seed(0)
    net = UntanglerNet(replace(TINY, head=head, activation=activation)).double()
    with torch.no_grad():
        net.out.weight.normal_()  # away from the small initialisation, so every term matters
        net.out.bias.normal_()
    f, h, _ = sample_batch(rng, 64)
    h[:32, 1:] = rng.uniform(-0.9, 0.9, (32, 4)) * TINY.h_band  # inside the blend band
    return net, torch.from_numpy(f), torch.from_numpy(h)


@pytest.mark.parametrize("head", ["pools", "residual"])
@pytest.mark.parametrize("activation", ["relu", "silu"])
def test_explicit_jacobian_matches_autograd(head, activation):
    net, ft, ht = _jacobian_case(head, activation, np.random.default_rng(1))
    values, jac = net.with_jacobian(ft, ht)
    auto = torch.autograd.functional.jacobian(lambda a, b: net(a, b).sum(0), (ft, ht))
    auto = torch.cat(auto, dim=2).permute(1, 0, 2)  # (B, 5, 10)
    torch.testing.assert_close(values, net(ft, ht), rtol=0, atol=1e-12)
    torch.testing.assert_close(jac, auto, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("head", ["pools", "residual"])
@pytest.mark.parametrize("activation", ["relu", "silu"])
def test_jacobian_row_is_the_row_weighted_jacobian(head, activation):
    rng = np.random.default_rng(2)
    net, ft, ht = _jacobian_case(head, activation, rng)
    values, jac = net.with_jacobian(ft, ht)
    for row in [*torch.eye(5, dtype=torch.float64), torch.from_numpy(rng.normal(size=5))]:
        f_row, jac_row = net.with_jacobian_row(ft, ht, row[None])
        torch.testing.assert_close(f_row, values, rtol=0, atol=0)
        torch.testing.assert_close(jac_row, row @ jac, rtol=1e-10, atol=1e-10)


def test_training_is_deterministic_and_resumable(tiny_net, tmp_path):
    checkpoint = tmp_path / "untangler.ckpt"
    train(TINY, checkpoint, log=silent, stop_at=30)  # an interrupted run
    messages = []
    resumed = train(TINY, checkpoint, log=messages.append).net
    assert messages[0] == f"resumed from {checkpoint} at step 30"
    for (name, a), b in zip(tiny_net.state_dict().items(), resumed.state_dict().values(), strict=True):
        assert torch.equal(a, b), name


def test_training_reduces_the_error(tiny_net):
    torch.manual_seed(TINY.seed)
    before = evaluate(UntanglerNet(TINY), n=5000)
    after = evaluate(tiny_net, n=5000)
    for name in before:  # 80 steps of a 16-wide net: a start, most visible where corrections are large
        assert after[name]["near_surface_mean_mm"] < 0.9 * before[name]["near_surface_mean_mm"], name
    assert after["paper"]["mean_mm"] < 0.6 * before["paper"]["mean_mm"]


def test_export_round_trip(tiny_net, tmp_path):
    check = export(tiny_net, tmp_path, metrics={"evaluation": {}})
    assert set(check) == {
        "values.onnx:f",
        "jacobian.onnx:f",
        "jacobian.onnx:jacobian",
        "jacobian_row.onnx:f",
        "jacobian_row.onnx:jacobian_row",
        "jacobian_row.onnx:jacobian_row vs jacobian.onnx",
    }
    meta = json.loads((tmp_path / CONFIG_FILE).read_text())
    assert meta["config"]["hidden"] == TINY.hidden and meta["delta"] == TINY.delta
    neural = NeuralUntangler(tmp_path, threads=1)
    f, h = sample_layered(np.random.default_rng(3), 1000)
    out = neural(f, h)
    with torch.no_grad():
        values, jac = tiny_net.with_jacobian(torch.from_numpy(f).float(), torch.from_numpy(h).float())
    np.testing.assert_allclose(out.f, values.numpy(), rtol=0, atol=EXPORT_TOLERANCE["f"][0])
    np.testing.assert_allclose(out.jacobian, jac.numpy(), rtol=1e-4, atol=1e-4)
    for k in range(5):
        np.testing.assert_allclose(
            neural(f, h, row=k).jacobian[:, 0], jac[:, k].numpy(), rtol=1e-4, atol=1e-4
        )
    assert np.abs(out.f - untangle(f, h)).max() < 0.5  # a tiny net, but an untangler


def test_reexport_rebuilds_the_network_from_the_values_graph(tiny_net, tmp_path):
    export(tiny_net, tmp_path)
    net = load_exported(tmp_path)
    for (name, a), b in zip(tiny_net.state_dict().items(), net.state_dict().values(), strict=True):
        assert torch.equal(a, b), name
    (tmp_path / "jacobian_row.onnx").unlink()
    check = reexport_row(tmp_path)
    assert max(check.values()) < 1e-4 and (tmp_path / "jacobian_row.onnx").is_file()
    meta = json.loads((tmp_path / CONFIG_FILE).read_text())
    (tmp_path / CONFIG_FILE).write_text(json.dumps(meta | {"config": meta["config"] | {"hidden": 8}}))
    with pytest.raises(ValueError, match="hidden"):
        load_exported(tmp_path)  # the weights do not fit the config


def test_export_raises_beyond_tolerance(tiny_net, tmp_path, monkeypatch):
    monkeypatch.setitem(EXPORT_TOLERANCE, "jacobian", (-1.0, 0.0))
    with pytest.raises(RuntimeError, match="output 'jacobian' differs from torch"):
        export(tiny_net, tmp_path)


def test_export_raises_when_the_row_graph_is_beyond_tolerance(tiny_net, tmp_path, monkeypatch):
    monkeypatch.setitem(EXPORT_TOLERANCE, "jacobian_row", (-1.0, 0.0))
    with pytest.raises(RuntimeError, match="jacobian_row.onnx:jacobian_row differs from torch"):
        export(tiny_net, tmp_path)


def test_export_command_writes_the_finished_checkpoint(tmp_path, capsys):
    """``python -m export.untangler`` exports the checkpoint ``python -m training.untangler`` left, with
    its training time and threads, and refuses an unfinished one naming the step."""
    checkpoint, out = tmp_path / "untangler.ckpt", tmp_path / "models"
    train(TINY, checkpoint, log=silent, stop_at=30)
    with pytest.raises(SystemExit, match="stopped at step 30 of 80"):
        export_untangler.main(["--checkpoint", str(checkpoint), "--out", str(out)])
    with pytest.raises(SystemExit, match="no training run"):
        export_untangler.main(["--checkpoint", str(tmp_path / "none.ckpt"), "--out", str(out)])
    trained = train(TINY, checkpoint, log=silent)
    export_untangler.main(["--checkpoint", str(checkpoint), "--out", str(out)])
    for (name, a), b in zip(trained.net.state_dict().items(), load_exported(out).state_dict().values(),
                            strict=True):  # fmt: skip
        assert torch.equal(a, b), name
    meta = json.loads((out / CONFIG_FILE).read_text())
    assert meta["train_seconds"] == round(trained.seconds, 1) and meta["torch_threads"] == 1
    assert set(meta["evaluation"]) == set(evaluate(trained.net, n=10))
