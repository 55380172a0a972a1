"""Explicit garment model: fits its training drapes, survives a save/load round trip, and a tiny
drape dataset builds end to end (resumable) and trains."""

import json

import numpy as np
import pytest

from service.pipeline.explicit import ExplicitModel
from training.drape.dataset import DatasetConfig, build_dataset, load_split, sample_betas
from training.explicit import ExplicitConfig, fit_explicit, pca


def _synthetic(n=16, V=40, seed=0):
    """Canonical 'drapes' that depend smoothly and nonlinearly on beta."""
    rng = np.random.default_rng(seed)
    betas = sample_betas(n, seed=5)
    template = rng.normal(0, 0.2, (V, 3))
    modes = rng.normal(0, 0.01, (3, V, 3))
    canonical = template + np.einsum("bk,kvd->bvd", np.tanh(2 * betas - 1) + betas**2, modes)
    return betas, canonical


def test_pca_recovers_a_low_rank_basis():
    rng = np.random.default_rng(0)
    data = rng.normal(size=(20, 2)) @ rng.normal(size=(2, 30)) + 5.0
    mean, basis = pca(data, 10, 0.999999)
    assert basis.shape == (2, 30)
    np.testing.assert_allclose(basis @ basis.T, np.eye(2), atol=1e-12)
    np.testing.assert_allclose((data - mean) @ basis.T @ basis + mean, data, atol=1e-10)


def test_explicit_model_reproduces_its_training_samples(tmp_path):
    betas, canonical = _synthetic()
    model = fit_explicit("tshirt", betas, canonical, ExplicitConfig(iterations=500))
    for i in (0, 7):
        err = np.linalg.norm(model.canonical(betas[i]) - canonical[i], axis=1)
        assert err.max() < 1e-3, "within 1 mm of a training drape"
    loaded = ExplicitModel.load("tshirt", model.save(tmp_path / "tshirt.npz").parent)
    np.testing.assert_array_equal(loaded.canonical(betas[3]), model.canonical(betas[3]))


def test_explicit_model_matches_torch_forward():
    torch = pytest.importorskip("torch")
    betas, canonical = _synthetic()
    model = fit_explicit("tshirt", betas, canonical, ExplicitConfig(iterations=50))
    layers = []
    for i, (w, b) in enumerate(zip(model.weights, model.biases, strict=True)):
        lin = torch.nn.Linear(w.shape[1], w.shape[0]).double()
        lin.weight.data, lin.bias.data = (
            torch.from_numpy(w.astype(np.float64)),
            torch.from_numpy(b.astype(np.float64)),
        )
        layers += [lin] + ([torch.nn.Tanh()] if i < len(model.weights) - 1 else [])
    net = torch.nn.Sequential(*layers)
    x = torch.from_numpy((betas - model.beta_shift) / model.beta_scale)
    np.testing.assert_allclose(model.coefficients(betas), net(x).detach().numpy(), atol=1e-10)


def test_tiny_drape_dataset_builds_resumes_and_trains(tmp_path):
    config = DatasetConfig(n_train=2, n_test=1, garments=("shorts",))
    record = build_dataset(tmp_path, config, workers=2)
    assert record["bodies"] == 3
    shapes = json.loads((tmp_path / "shapes.json").read_text())
    assert shapes["betas"]["train"] != shapes["betas"]["test"]
    train = load_split(tmp_path, "train", "shorts")
    assert train["world"].shape[:2] == (2, 3442) and np.all(np.isfinite(train["canonical"]))
    # No simulated vertex more than 1 mm inside its body.
    assert train["stats"][:, 3].min() > -1e-3
    # Resuming finds nothing left to do.
    assert build_dataset(tmp_path, config, workers=1)["bodies"] == 3
    model = fit_explicit("shorts", train["beta"], train["canonical"].astype(np.float64))
    err = np.linalg.norm(model.canonical(train["beta"][1]) - train["canonical"][1], axis=1)
    assert err.mean() < 1e-3


def test_committed_onnx_explicit_models_match_the_numpy_reference():
    pytest.importorskip("onnxruntime")
    from service.pipeline.catalog import load_catalog
    from service.pipeline.explicit import ONNX_TOLERANCE, ExplicitModel, ExplicitOnnx
    from training.drape.dataset import sample_betas

    for gid in load_catalog():
        reference, onnx_model = ExplicitModel.load(gid), ExplicitOnnx(gid)
        for beta in sample_betas(4, 5):
            np.testing.assert_allclose(
                onnx_model.canonical(beta), reference.canonical(beta), atol=ONNX_TOLERANCE
            )
