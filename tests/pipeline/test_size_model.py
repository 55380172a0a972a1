"""A garment worn in a size (issue 56, ``service.pipeline.size_model``): delta, the size model's offset
and the committed size models: a size up hangs further off the body, the one-size garment is delta 0."""

from __future__ import annotations

import numpy as np
import pytest

from service.pipeline.explicit import ExplicitModel
from service.pipeline.size_model import SizeModel, follow_cut, size_delta
from service.pipeline.sizes import LETTERS
from service.pipeline.sizing import load_sizes
from service.process.paths import models_dir

STYLES = tuple(load_sizes()["styles"])


def test_delta_is_zero_for_the_one_size_cut_and_grows_with_the_size():
    mean, grading = np.array([95.0, 170.0]), 0.7
    assert np.array_equal(follow_cut(mean, mean, grading), mean)  # the mean body wears the template's cut
    wearer = np.array([115.0, 180.0])
    one_size = follow_cut(wearer, mean, grading)
    assert one_size == pytest.approx([109.0, 177.0])  # 70 % of the way to the body
    assert size_delta(one_size, wearer, mean, grading) == pytest.approx([0.0, 0.0])
    assert size_delta(np.array([120.0, 177.0]), wearer, mean, grading)[0] > 0
    assert size_delta(np.array([100.0, 186.0]), wearer, mean, grading) == pytest.approx(
        [np.log(100 / 109), np.log(186 / 177)]
    )


def synthetic(V: int = 5, K: int = 2, seed: int = 0) -> SizeModel:
    rng = np.random.default_rng(seed)
    basis = np.linalg.qr(rng.normal(size=(V * 3, K)))[0].T.reshape(K, V, 3).astype(np.float16)
    weights = [rng.normal(size=(4, 5)).astype(np.float32), rng.normal(size=(2 * K, 4)).astype(np.float32)]
    biases = [rng.normal(size=4).astype(np.float32), rng.normal(size=2 * K).astype(np.float32)]
    coder = ExplicitModel("g", None, None, None, None, [], [], None, None)  # q is x
    sizes = np.column_stack([np.linspace(80, 130, 6), np.linspace(165, 190, 6)])
    return SizeModel("g", LETTERS, "men", sizes, "chest", np.array([95.0, 170.0]), 0.7, basis, np.zeros(5),
                     np.ones(5), weights, biases, coder)  # fmt: skip


def test_the_offset_is_delta_times_the_network_on_the_basis():
    model, beta, delta = synthetic(), np.array([0.3, -0.2, 0.5]), np.array([0.05, -0.02])
    follow = np.arange(15, dtype=np.float64).reshape(5, 3)
    assert np.array_equal(model.canonical(follow, beta, np.zeros(2)), follow)
    h = np.tanh(np.concatenate([beta, delta]) @ model.weights[0].T.astype(np.float64) + model.biases[0])
    out = h @ model.weights[1].T.astype(np.float64) + model.biases[1]
    c = 0.05 * out[:2] - 0.02 * out[2:]
    expected = follow + np.tensordot(c, model.basis.astype(np.float64), axes=1)
    assert np.allclose(model.canonical(follow, beta, delta), expected, atol=1e-12)


def test_a_size_model_survives_its_file(tmp_path):
    model = synthetic()
    ExplicitModel("g", np.zeros((5, 3), np.float32), np.zeros((1, 5, 3), np.float16), np.zeros(3), np.ones(3),
                  [np.zeros((1, 3), np.float32)], [np.zeros(1, np.float32)], np.zeros((5, 3), np.float32),
                  np.tile(np.eye(3, dtype=np.float32), (5, 1, 1))).save(tmp_path / "g.npz")  # fmt: skip
    model.save(tmp_path / "g.size.npz")
    back = SizeModel.load("g", tmp_path)
    assert back.letters == LETTERS and back.primary == "chest"
    wearer, beta, delta = np.array([100.0, 175.0]), np.array([0.1, 0.2, 0.3]), np.array([0.07, 0.01])
    assert np.array_equal(back.delta("M", wearer), model.delta("M", wearer))
    assert np.allclose(back.offset(beta, delta), model.offset(beta, delta))
    assert SizeModel.load("missing", tmp_path) is None


@pytest.mark.parametrize("style", STYLES)
def test_each_style_with_sizes_has_a_size_model_and_a_size_up_hangs_further_off(style: str):
    model = SizeModel.load(style)
    assert model is not None, f"models/explicit/{style}.size.npz missing (python -m training.explicit_sizes)"
    assert model.letters == LETTERS
    assert np.all(np.diff(model.size_cm[:, 0]) > 0)  # each size wider than the one before
    explicit = ExplicitModel.load(style)
    beta = np.zeros(3)
    follow = explicit.canonical(beta)
    deltas = (np.array([-0.08, 0.0]), np.zeros(2), np.array([0.08, 0.0]))
    height = [explicit.encode(model.canonical(follow, beta, d))[:, 2].mean() for d in deltas]
    assert height[0] < height[1] < height[2], height  # the body-offset height of the mean vertex
    assert models_dir().joinpath("explicit", f"{style}.size.npz").stat().st_size < 2_000_000
