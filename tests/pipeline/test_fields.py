"""Neural fields: HRBF covariant field, ground-truth signs, network gradients, ONNX export."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from service.geometry.closest import ClosestPoint
from service.geometry.intersections import intersecting_pairs
from service.geometry.mesh import vertex_normals
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.catalog import load_catalog
from training.fields.hrbf import build_openings, covariant_field, fit_hrbf
from training.fields.net import FieldConfig, FieldNet
from training.fields.samples import signed_distance


def test_hrbf_interpolates_values_and_gradients():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    points = np.stack([0.1 * np.cos(t), 0.1 * np.sin(t), 0.02 * np.sin(3 * t)], 1)
    normals = rng.normal(size=points.shape) * 0.2 + [0, 0, 1]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    hrbf = fit_hrbf(points, normals, 0.1, np.array([0.0, 0.0, 1.0]), 0.0)
    h, grad = hrbf(points)
    assert np.abs(h).max() < 1e-9
    assert np.abs(grad - normals).max() < 1e-8


def test_hrbf_gradient_matches_finite_differences():
    rng = np.random.default_rng(1)
    points = rng.normal(size=(12, 3)) * 0.05
    normals = rng.normal(size=(12, 3))
    hrbf = fit_hrbf(points, normals, 0.08, np.array([0.3, -0.2, 0.9]), 0.01)
    x = rng.normal(size=(50, 3)) * 0.06
    _, grad = hrbf(x)
    eps = 1e-6
    fd = np.stack([(hrbf(x + eps * e)[0] - hrbf(x - eps * e)[0]) / (2 * eps) for e in np.eye(3)], 1)
    assert np.abs(fd - grad).max() < 1e-6


def test_hrbf_is_the_plane_beyond_its_support():
    points = np.array([[0.0, 0, 0], [0.05, 0, 0], [0, 0.05, 0]])
    hrbf = fit_hrbf(points, np.tile([0.0, 0, 1], (3, 1)) + 0.1, 0.05, np.array([0.0, 0, 1]), 0.0)
    far = np.array([[1.0, 1.0, 0.5], [-1.0, 0.3, -0.2]])
    h, grad = hrbf(far)
    np.testing.assert_allclose(h, far[:, 2], atol=1e-12)
    np.testing.assert_allclose(grad, [[0, 0, 1], [0, 0, 1]], atol=1e-12)


@pytest.fixture(scope="module")
def tshirt():
    g = load_catalog()["tshirt"]
    return g, build_openings(g.vertices, g.faces, g.openings)


def test_covariant_field_signs_through_and_away_from_openings(tshirt):
    g, openings = tshirt
    # Beyond every opening, along its outward axis: positive, rising with distance.
    for o in openings:
        beyond = o.origin + np.outer([0.02, 0.05, 0.1], o.axis)
        h, _ = covariant_field(openings, beyond)
        assert np.all(h > 0) and np.all(np.diff(h) > 0)
    # Over the garment, away from its openings: negative.
    on_loop = np.zeros(len(g.vertices), dtype=bool)
    for loop in g.openings.values():
        on_loop[loop] = True
    dist = np.linalg.norm(g.vertices[:, None] - g.vertices[on_loop][None], axis=2).min(1)
    h, _ = covariant_field(openings, g.vertices[dist > 0.03])
    assert h.max() < 0
    # Zero at the HRBF centres; on the rest of the loops (between centres) within 2 mm of zero.
    for o in openings:
        assert np.abs(o.hrbf(o.hrbf.centres)[0]).max() < 1e-9
    h, _ = covariant_field(openings, g.vertices[on_loop])
    assert np.abs(h).max() < 0.002


def test_covariant_field_gradient_matches_finite_differences(tshirt):
    _, openings = tshirt
    rng = np.random.default_rng(3)
    x = openings[0].origin + rng.normal(scale=0.03, size=(200, 3))
    _, grad = covariant_field(openings, x)
    eps = 1e-6
    fd = np.stack(
        [(covariant_field(openings, x + eps * e)[0] - covariant_field(openings, x - eps * e)[0]) / (2 * eps)
         for e in np.eye(3)], 1,
    )  # fmt: skip
    # Points where the max / min switch branch have one-sided gradients: all but a few agree.
    agree = np.linalg.norm(fd - grad, axis=1) < 1e-5
    assert agree.mean() > 0.97


def winding_number(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Generalised winding number (van Oosterom-Strackee solid angles) of a closed mesh, per point."""
    out = []
    for chunk in np.array_split(points, max(1, len(points) // 200)):
        a, b, c = (vertices[faces[:, k]][None] - chunk[:, None] for k in range(3))
        la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
        det = np.einsum("pfd,pfd->pf", a, np.cross(b, c))
        den = (
            la * lb * lc + np.einsum("pfd,pfd->pf", a, b) * lc + np.einsum("pfd,pfd->pf", b, c) * la
            + np.einsum("pfd,pfd->pf", c, a) * lb
        )  # fmt: skip
        out.append(np.arctan2(det, den).sum(1) / (2 * np.pi))
    return np.concatenate(out)


def test_body_signed_distance_sign_agrees_with_winding_number():
    body = BodyModel.load()
    v = body.vertices(np.asarray(DEFAULT_BETA))
    rng = np.random.default_rng(4)
    idx = rng.choice(len(v), 600, replace=False)
    n = vertex_normals(v, body.faces)[idx]
    x = v[idx] + rng.choice([-1, 1], 600)[:, None] * rng.uniform(0.002, 0.03, 600)[:, None] * n
    # Anny's own mesh intersects itself between the toes, where inside is not defined: skip there.
    tangled = v[body.faces[intersecting_pairs(v, body.faces).reshape(-1)].reshape(-1)]
    far = np.linalg.norm(x[:, None] - tangled[None], axis=2).min(1) > 0.03
    assert far.mean() > 0.9
    f, grad = signed_distance(ClosestPoint.build(v, body.faces), x[far])
    inside = winding_number(x[far], v, body.faces) > 0.5
    assert np.array_equal(f < 0, inside)
    np.testing.assert_allclose(np.linalg.norm(grad, axis=1), 1.0, atol=1e-9)


def _net(fourier=8, seed=0):
    torch.manual_seed(seed)
    cfg = replace(FieldConfig(), width=16, depth=2, fourier=fourier)
    return FieldNet(cfg, np.array([0.0, 0.0, 1.0]), 0.8).double()


@pytest.mark.parametrize("fourier", [0, 8])
def test_network_gradient_graph_matches_autograd_and_finite_differences(fourier):
    net = _net(fourier)
    with torch.no_grad():  # random output weights of a realistic size
        net.out.weight.normal_(0, 1.0)
    rng = np.random.default_rng(5)
    x = torch.from_numpy(rng.normal(size=(64, 3)) * 0.3 + [0, 0, 1])
    beta = torch.tensor([[0.3, 0.5, 0.7]], dtype=torch.float64)
    f, h, gf, gh = net.with_gradient(x, beta)
    for a, b in zip(net.with_gradient(x, beta, h_gradient=False), (f, h, gf), strict=True):
        torch.testing.assert_close(a, b, atol=1e-12, rtol=0)  # one cotangent: the same f, h, grad f
    f0, h0 = net(x, beta)
    torch.testing.assert_close(f, f0, atol=1e-12, rtol=0)
    torch.testing.assert_close(h, h0, atol=1e-12, rtol=0)
    xg = x.clone().requires_grad_(True)
    fa, ha = net(xg, beta)
    (gfa,) = torch.autograd.grad(fa.sum(), xg, retain_graph=True)
    (gha,) = torch.autograd.grad(ha.sum(), xg)
    torch.testing.assert_close(gf, gfa, atol=1e-10, rtol=1e-8)
    torch.testing.assert_close(gh, gha, atol=1e-10, rtol=1e-8)
    eps = 1e-6
    with torch.no_grad():
        fd = torch.stack([(net(x + eps * e, beta)[0] - net(x - eps * e, beta)[0]) / (2 * eps)
                          for e in torch.eye(3, dtype=torch.float64)], 1)  # fmt: skip
    torch.testing.assert_close(gf, fd, atol=1e-7, rtol=1e-6)


def test_export_matches_torch_and_detects_a_wrong_graph(tmp_path, monkeypatch):
    from export import fields as export_fields
    from service.pipeline.fields import NeuralField

    net = _net(8).float()
    rng = np.random.default_rng(6)
    x = (rng.normal(size=(300, 3)) * 0.3 + [0, 0, 1]).astype(np.float32)
    beta = np.array([[0.2, 0.4, 0.6]], dtype=np.float32)
    check = export_fields.export_field(net, "probe", tmp_path, x, beta)
    assert max(check.values()) < 1e-4
    out = NeuralField("probe", tmp_path, threads=1)(x, beta[0], gradient=True)
    with torch.no_grad():
        ref = net.with_gradient(torch.from_numpy(x), torch.from_numpy(beta))
    np.testing.assert_allclose(out.grad_f, ref[2].numpy(), atol=1e-5)
    # The graph with grad f alone: the full graph's values and grad f, and zeros for grad h.
    alone = NeuralField("probe", tmp_path, threads=1)(x, beta[0], gradient="f")
    assert (tmp_path / "probe.gradf.onnx").is_file()
    for name in ("f", "h", "grad_f"):
        np.testing.assert_allclose(getattr(alone, name), getattr(out, name), atol=1e-6, rtol=0)
    assert np.all(alone.grad_h == 0)
    with pytest.raises(ValueError, match="gradient must be"):
        NeuralField("probe", tmp_path, threads=1)(x, beta[0], gradient="h")
    # A directory without it (a garment imported before it existed): the full graph, grad h dropped.
    (tmp_path / "probe.gradf.onnx").unlink()
    old = NeuralField("probe", tmp_path, threads=1)(x, beta[0], gradient="f")
    np.testing.assert_array_equal(old.grad_f, out.grad_f)
    assert np.all(old.grad_h == 0)
    # A graph that is not the network's must be refused, either gradient graph.
    for name in ("_WithGradient", "_WithFGradient"):
        with monkeypatch.context() as m:
            m.setattr(export_fields, name, _Broken)
            with pytest.raises(RuntimeError, match="differs from torch"):
                export_fields.export_field(net, "probe", tmp_path, x, beta)


def test_gradient_batches_agree_with_one_call(tmp_path, monkeypatch):
    from export import fields as export_fields
    from service.pipeline import fields as service_fields

    net = _net(8).float()
    rng = np.random.default_rng(8)
    x = (rng.normal(size=(300, 3)) * 0.3 + [0, 0, 1]).astype(np.float32)
    beta = np.array([[0.2, 0.4, 0.6]], dtype=np.float32)
    export_fields.export_field(net, "probe", tmp_path, x, beta)
    field = service_fields.NeuralField("probe", tmp_path, threads=1)
    whole = field(x, beta[0], gradient=True)
    monkeypatch.setattr(service_fields, "GRADIENT_BATCH", 64)  # 5 calls, the last one short
    for a, b in zip(field(x, beta[0], gradient=True), whole, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_committed_fields_answer_does_not_depend_on_its_batch(monkeypatch):
    """The served batch size (1,024) gives the answers of the old, larger batches bit for bit, on a
    committed field of full width: the GEMMs block their rows the same way at every batch size."""
    from service.pipeline import fields as service_fields

    field = service_fields.NeuralField("tshirt", service_fields.default_directory(), threads=1)
    rng = np.random.default_rng(10)
    x = rng.normal(size=(9000, 3)) * 0.15 + [0, 0, 1.3]
    beta = np.array([0.3, 0.5, 0.7])
    for gradient in (False, True, "f"):
        monkeypatch.setattr(service_fields, "BATCH", 1024)
        monkeypatch.setattr(service_fields, "GRADIENT_BATCH", 1024)
        small = field(x, beta, gradient)
        monkeypatch.setattr(service_fields, "BATCH", 8192)
        monkeypatch.setattr(service_fields, "GRADIENT_BATCH", 4096)
        large = field(x, beta, gradient)
        for a, b in zip(small, large, strict=True):
            np.testing.assert_array_equal(a, b)


def test_gradient_graph_reexports_from_the_values_graph(tmp_path):
    """``load_exported`` reads back the exact parameters; the re-exported gradient graph matches."""
    from export import fields as export_fields
    from service.pipeline.fields import NeuralField

    net = _net(8).float()
    rng = np.random.default_rng(7)
    x = (rng.normal(size=(300, 3)) * 0.3 + [0, 0, 1]).astype(np.float32)
    beta = np.array([[0.2, 0.4, 0.6]], dtype=np.float32)
    check = export_fields.export_field(net, "probe", tmp_path, x, beta)
    export_fields.write_config(tmp_path, {"probe": export_fields.field_entry(net, check, {}, 0.0)})
    loaded = export_fields.load_exported("probe", tmp_path)
    for (name, p), (name_q, q) in zip(net.state_dict().items(), loaded.state_dict().items(), strict=True):
        assert name == name_q
        torch.testing.assert_close(p, q, atol=0, rtol=0)
    before = NeuralField("probe", tmp_path, threads=1)(x, beta[0], gradient=True)
    (tmp_path / "probe.gradf.onnx").unlink()  # a directory exported before the grad-f graph existed
    regrad = export_fields.reexport_gradient("probe", tmp_path, x, beta)
    assert set(regrad) == {
        "grad:f",
        "grad:h",
        "grad:grad_f",
        "grad:grad_h",
        "gradf:f",
        "gradf:h",
        "gradf:grad_f",
    }
    assert (tmp_path / "probe.gradf.onnx").is_file()
    after = NeuralField("probe", tmp_path, threads=1)(x, beta[0], gradient=True)
    for a, b in zip(after, before, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)
    alone = NeuralField("probe", tmp_path, threads=1)(x, beta[0], gradient="f")
    for a, b in zip(alone[:3], before[:3], strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)


class _Broken(torch.nn.Module):
    def __init__(self, net):
        super().__init__()
        self.net = net

    def forward(self, x, beta):
        f, h, gf, gh = self.net.with_gradient(x, beta)
        return f, h, gf * 1.01, gh


def test_committed_fields_reproduce_their_recorded_held_out_errors():
    """The ONNX files in models/fields give the held-out errors fields.json records (computed with torch
    at training time), and the T-shirt meets the 1.5 mm target of the field issue."""
    import json

    from service.pipeline.fields import FieldSet, default_directory
    from training.fields.train import Surfaces, field_errors, held_out

    recorded = json.loads((default_directory() / "fields.json").read_text())["fields"]
    fields = FieldSet(threads=1)
    for fid in ("tshirt", "body"):
        err = field_errors(lambda x, b, fid=fid: fields.fields[fid](x, b[0])[:2], held_out(Surfaces(fid)))
        assert err["f_mm"] == pytest.approx(recorded[fid]["held_out"]["f_mm"], abs=0.01)
        if fid != "body":  # the served body h is the constant -1, not the network's
            assert err["h_mm"] == pytest.approx(recorded[fid]["held_out"]["h_mm"], abs=0.01)
    assert recorded["tshirt"]["held_out"]["f_mm"] <= 1.5 and recorded["tshirt"]["held_out"]["h_mm"] <= 1.5


def test_batches_on_two_threads_agree_with_one_call_on_one(tmp_path, monkeypatch):
    """``run_blocks`` cuts a call into batches run side by side: the answer of one call, bit for bit."""
    from export import fields as export_fields
    from service.pipeline import fields as service_fields
    from service.process import onnx_session

    net = _net(8).float()
    rng = np.random.default_rng(9)
    x = (rng.normal(size=(5000, 3)) * 0.3 + [0, 0, 1]).astype(np.float32)
    beta = np.array([[0.2, 0.4, 0.6]], dtype=np.float32)
    export_fields.export_field(net, "probe", tmp_path, x[:300], beta)
    one = service_fields.NeuralField("probe", tmp_path, threads=1)
    two = service_fields.NeuralField("probe", tmp_path, threads=2)
    monkeypatch.setattr(service_fields, "BATCH", 1000)
    monkeypatch.setattr(service_fields, "GRADIENT_BATCH", 700)
    calls = []
    run = onnx_session.blocks
    monkeypatch.setattr(onnx_session, "blocks", lambda *a: calls.append(run(*a)) or calls[-1])
    for gradient in (False, True, "f"):
        whole = one(x, beta[0], gradient)
        split = two(x, beta[0], gradient)
        for a, b in zip(split, whole, strict=True):
            np.testing.assert_array_equal(a, b)
    assert [len(c) for c in calls] == [5, 6, 8, 8, 8, 8]  # batches, an even count on two threads


def test_blocks_cover_the_points_in_order_as_a_multiple_of_the_threads():
    from service.process.onnx_session import MIN_BLOCK, blocks

    for n, batch, threads in [(30000, 8192, 2), (30000, 4096, 2), (5000, 8192, 2), (2047, 8192, 2),
                              (300, 64, 2), (0, 8192, 2), (30000, 8192, 1), (9000, 4096, 3)]:  # fmt: skip
        parts = blocks(n, batch, threads)
        assert parts[0].start == 0 and parts[-1].stop == n
        assert all(a.stop == b.start for a, b in zip(parts[:-1], parts[1:], strict=True))
        assert max(p.stop - p.start for p in parts) <= batch
        if threads > 1 and n >= threads * MIN_BLOCK:
            assert len(parts) % threads == 0
        else:
            assert len(parts) == max(1, -(-n // batch))
    assert len(blocks(30000, 8192, 2)) == 4 and len(blocks(30000, 4096, 2)) == 8
    assert len(blocks(5000, 8192, 2)) == 2 and len(blocks(2047, 8192, 2)) == 1
