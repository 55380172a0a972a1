"""A tiny field training end to end (seconds): ground truth, training, resume, held-out error, export."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from export import fields as export_fields  # noqa: E402
from export.fields import export_field  # noqa: E402
from service.pipeline.fields import NeuralField  # noqa: E402
from training.fields import train as field_train  # noqa: E402
from training.fields.net import FieldConfig, FieldNet  # noqa: E402

TINY = replace(
    FieldConfig(), width=16, depth=2, fourier=8, steps=100, lr=1e-2, batch=512, n_betas=2,
    points_per_beta=1024,
)


@pytest.fixture
def dirs(tmp_path, monkeypatch):
    monkeypatch.setattr(field_train, "DATA_DIR", tmp_path / "data")
    monkeypatch.setattr(field_train, "CHECKPOINT_DIR", tmp_path / "build")
    monkeypatch.setattr(field_train, "CHECKPOINT_EVERY", 10)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield tmp_path
    torch.set_num_threads(threads)


def test_tiny_training_learns_resumes_and_exports(dirs):
    surfaces = field_train.Surfaces("tshirt")
    quiet = lambda _: None  # noqa: E731
    result = field_train.train_field(surfaces, TINY, name="a", log=quiet)
    tests = field_train.held_out(surfaces, n_per_beta=256)[:2]
    torch.manual_seed(TINY.seed)
    untrained = FieldNet(TINY, *surfaces.box())
    before = field_train.field_errors(field_train.torch_predict(untrained), tests)
    after = field_train.field_errors(field_train.torch_predict(result.net), tests)
    # Near the surface f is within 1 cm of 0 (as an untrained network predicts); h is far from it there.
    assert after["h_mm"] < 0.5 * before["h_mm"], (before, after)
    # Interrupted at step 50 and resumed: the same weights as the uninterrupted run.
    field_train.train_field(surfaces, TINY, name="b", log=quiet, stop_at=50)
    resumed = field_train.train_field(surfaces, TINY, name="b", log=quiet)
    for p, q in zip(result.net.parameters(), resumed.net.parameters(), strict=True):
        torch.testing.assert_close(p, q, atol=0, rtol=0)
    assert field_train.load_trained(surfaces, "b") is not None
    # Export and serve: onnxruntime agrees with torch on the held-out points.
    beta, samples = tests[0]
    x = samples.x.astype(np.float32)
    export_field(result.net, "tshirt", dirs / "models", x, beta[None].astype(np.float32))
    served = NeuralField("tshirt", dirs / "models", threads=1)(x, beta)
    with torch.no_grad():
        f, h = result.net(torch.from_numpy(x), torch.from_numpy(beta[None].astype(np.float32)))
    np.testing.assert_allclose(served.f, f.numpy(), atol=1e-5)
    np.testing.assert_allclose(served.h, h.numpy(), atol=1e-5)


def test_export_command_writes_the_finished_checkpoint(dirs):
    """``python -m export.fields ID --out DIR`` serves the network ``python -m training.fields ID`` left,
    with its held-out errors and training time; without a finished checkpoint it refuses, naming the id."""
    out = dirs / "out"
    surfaces = field_train.Surfaces("tshirt")
    with pytest.raises(SystemExit, match="no finished checkpoint of tshirt"):
        export_fields.main(["tshirt", "--out", str(out)])
    result = field_train.train_field(surfaces, TINY, log=lambda _: None)
    export_fields.main(["tshirt", "--out", str(out)])
    entry = json.loads((out / "fields.json").read_text())["fields"]["tshirt"]
    assert entry["train_seconds"] == round(result.seconds, 1)
    expected = field_train.field_errors(field_train.torch_predict(result.net), field_train.held_out(surfaces))
    assert entry["held_out"] == pytest.approx(expected, rel=1e-9)
    centre = surfaces.box()[0]
    x = (centre + np.random.default_rng(0).uniform(-0.1, 0.1, (500, 3))).astype(np.float32)
    beta = np.array([0.3, 0.5, 0.5], np.float32)
    served = NeuralField("tshirt", out, threads=1)(x, beta)
    with torch.no_grad():
        f, h = result.net(torch.from_numpy(x), torch.from_numpy(beta[None]))
    np.testing.assert_allclose(served.f, f.numpy(), atol=1e-5)
    np.testing.assert_allclose(served.h, h.numpy(), atol=1e-5)
