"""Explicit garment model: fits its training drapes, survives a save/load round trip, and a tiny
drape dataset builds end to end (resumable) and trains."""

import json

import numpy as np
import pytest

from service.pipeline.explicit import SOFT, ExplicitModel, decode_height, encode_height
from training.drape import population
from training.drape.dataset import (
    DatasetConfig,
    box_corners,
    build_dataset,
    load_split,
    sample_betas,
    split_betas,
)
from training.explicit import ExplicitConfig, fit_explicit, mean_body, pca

PLAIN = ExplicitConfig(offsets=False)


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
    model = fit_explicit("tshirt", betas, canonical, ExplicitConfig(iterations=500, offsets=False))
    for i in (0, 7):
        err = np.linalg.norm(model.canonical(betas[i]) - canonical[i], axis=1)
        assert err.max() < 1e-3, "within 1 mm of a training drape"
    loaded = ExplicitModel.load("tshirt", model.save(tmp_path / "tshirt.npz").parent)
    np.testing.assert_array_equal(loaded.canonical(betas[3]), model.canonical(betas[3]))


def test_explicit_model_matches_torch_forward():
    torch = pytest.importorskip("torch")
    betas, canonical = _synthetic()
    model = fit_explicit("tshirt", betas, canonical, ExplicitConfig(iterations=50, offsets=False))
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
    config = DatasetConfig(n_train=2, n_test=1, garments=("shorts",), corners=False)
    record = build_dataset(tmp_path, config, workers=2)
    assert record["bodies"] == 3
    shapes = json.loads((tmp_path / "shapes.json").read_text())
    assert shapes["betas"]["train"] != shapes["betas"]["test"]
    assert len(shapes["people"]["train"]) == 2 and len(shapes["people"]["test"]) == 1
    train = load_split(tmp_path, "train", "shorts")
    assert train["world"].shape[:2] == (2, 3442) and np.all(np.isfinite(train["canonical"]))
    # Each drape holds the body the service serves to its adult, not the box body of its code.
    person = population.people(1, "train")[0]
    np.testing.assert_allclose(train["body"][0], person[2].astype(np.float32))
    np.testing.assert_array_equal(train["beta"][0], person[1])
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


def test_height_code_is_a_c1_bijection_onto_positive_heights():
    d = np.geomspace(1e-5, 0.5, 2001)
    np.testing.assert_allclose(decode_height(encode_height(d)), d, rtol=1e-12)
    u = np.linspace(-1.0, 1.0, 20001)
    assert np.all(decode_height(u) > 0) and np.all(np.diff(decode_height(u)) > 0)
    # C1 at the join: both one-sided slopes are 1.
    eps = 1e-9
    left = (decode_height(SOFT) - decode_height(SOFT - eps)) / eps
    right = (decode_height(SOFT + eps) - decode_height(SOFT)) / eps
    np.testing.assert_allclose([left, right], [1.0, 1.0], rtol=1e-5)


def _hugging(n=12, seed=0):
    """Synthetic canonical 'drapes' 0.5-6 mm off the front of the mean body's torso (convex there),
    closer for heavier betas, as taut cloth on a big body; ``(betas, drapes, body)``."""
    body = mean_body()
    rng = np.random.default_rng(seed)
    betas = sample_betas(n, seed=5)
    q = body.query(body.vertices)
    z = body.vertices[:, 2]
    front = (q.normal[:, 1] < -0.7) & (np.abs(body.vertices[:, 0]) < 0.12) & (z > 0.15) & (z < 0.55)
    pick = rng.choice(np.flatnonzero(front), 200, replace=False)
    q = body.query(body.vertices[pick])
    gap = 0.0005 + 0.0055 * (1 - betas[:, 2:3]) ** 2  # (B, 1): 6 mm at weight 0, 0.5 mm at weight 1
    drapes = q.point[None] + gap[:, :, None] * q.normal[None]
    return betas, drapes, body


def test_body_offset_model_reproduces_drapes_and_never_sinks_when_extrapolating():
    betas, drapes, body = _hugging()
    offsets = fit_explicit("tshirt", betas, drapes, ExplicitConfig(iterations=300), body=body)
    assert offsets.anchor is not None
    err = np.linalg.norm(offsets.canonical(betas[3]) - drapes[3], axis=1)
    assert err.max() < 5e-4
    plain = fit_explicit("tshirt", betas, drapes, PLAIN, body=body)
    # Beyond the heaviest training shape the plain model's trend runs into the body: all of it.
    # The body-offset one stays above every anchor's tangent plane (exactly, by construction), so
    # only vertices that slid over a concave patch of the torso (under the chest) dip in.
    beyond = np.array([0.5, 0.5, 1.6])
    assert np.mean(body.query(plain.canonical(beyond)).signed < 0) > 0.9
    x = offsets.canonical(beyond)
    height = np.einsum("vkx,vx->vk", offsets.frame.astype(np.float64), x - offsets.anchor)[:, 2]
    assert np.all(height > 0)
    assert np.mean(body.query(x).signed < 0) < 0.1


def test_body_offset_model_survives_save_load_and_onnx_export(tmp_path):
    pytest.importorskip("onnxruntime")
    from export.explicit import export_explicit
    from service.pipeline.explicit import ONNX_TOLERANCE, ExplicitOnnx

    betas, drapes, body = _hugging()
    model = fit_explicit("tshirt", betas, drapes, ExplicitConfig(iterations=50), body=body)
    loaded = ExplicitModel.load("tshirt", model.save(tmp_path / "tshirt.npz").parent)
    np.testing.assert_array_equal(loaded.canonical(betas[2]), model.canonical(betas[2]))
    assert export_explicit("tshirt", tmp_path) <= ONNX_TOLERANCE
    onnx_model = ExplicitOnnx("tshirt", tmp_path)
    for beta in (betas[0], np.array([1.0, 0.72, 1.0])):
        np.testing.assert_allclose(onnx_model.canonical(beta), model.canonical(beta), atol=ONNX_TOLERANCE)


def test_corners_are_training_shapes_inside_the_box_and_held_out_at_its_extremes():
    config = DatasetConfig(n_train=14, source="box")
    splits = split_betas(config)
    train, test = splits["train"], splits["test"]
    assert len(train) == config.n_train + 8 and len(test) == config.n_test + 4
    np.testing.assert_array_equal(train[: config.n_train], sample_betas(config.n_train, 1))
    np.testing.assert_array_equal(test[-4:], box_corners(extremes_only=True))
    # No training shape is a test shape, and the extremes lie outside every training shape's box.
    assert min(np.abs(t - u).max() for t in train for u in test) > 0.05
    assert np.all(test[-4:, 2] <= train[:, 2].min()) or np.all(test[-4:, 2] >= 0)
    assert train[:, 1].max() < box_corners(extremes_only=True)[:, 1].max()
    assert train[:, 1].min() > box_corners(extremes_only=True)[:, 1].min()


def test_served_explicit_garments_stay_out_of_the_body_at_every_corner_of_the_box():
    """Issue 21's bound (0.3 % of a garment's vertices inside the body, ``untangle: false``) on the 8
    exact corners of the supported box, which no training shape is."""
    pytest.importorskip("onnxruntime")
    from service.geometry.closest import ClosestPoint
    from service.pipeline.collisions.settings import SETTINGS
    from service.pipeline.outfit import OutfitModels, make_outfit

    models = OutfitModels.load(threads=1)
    for beta in box_corners():
        for gid in models.catalog:
            outfit = make_outfit(models, [gid], beta, untangle_layers=False, measure=False)
            body = ClosestPoint.build(outfit.body_vertices, outfit.body_faces)
            assert np.mean(body.query(outfit.garments[0][1]).signed < 0) <= 0.003, (gid, beta)
    # The clearance step itself: points inside the mean body come out to CLEARANCE, others stay.
    mean = models.space.closest
    x = mean.vertices[::500] - 0.002 * mean.query(mean.vertices[::500]).normal  # 2 mm inside
    moved = models.clearance.clear_of_body(x)
    assert np.all(mean.query(moved).signed > 0.5 * SETTINGS.clearance)  # out, about at the clearance
    far = mean.vertices[::500] + 0.02 * mean.query(mean.vertices[::500]).normal
    np.testing.assert_array_equal(models.clearance.clear_of_body(far), far)


def test_the_box_part_of_the_training_set_is_the_box_drapes_or_the_box_models_standing_in(tmp_path):
    from training.drape.dataset import DatasetConfig, box_corners
    from training.explicit import BOX_STANDIN_CODES, box_training

    betas, canonical = _synthetic()
    model = fit_explicit("tshirt", betas, canonical, ExplicitConfig(iterations=50, offsets=False))
    model.save(tmp_path / "models" / "tshirt.npz")
    codes, meshes = box_training("tshirt", None, tmp_path / "models")
    # Sobol codes of the box, then its 8 inset corners, as the box dataset's training split held them.
    assert codes.shape == (BOX_STANDIN_CODES + 8, 3) and np.all((codes >= 0.0) & (codes <= 1.0))
    corners = box_corners(DatasetConfig(source="box").corner_inset)
    np.testing.assert_array_equal(codes[BOX_STANDIN_CODES:], corners)
    for k in (7, BOX_STANDIN_CODES + 3):
        np.testing.assert_allclose(meshes[k], model.canonical(codes[k]))
    none, nothing = box_training("tshirt", None, None)
    assert none.shape == (0, 3) and nothing is None
