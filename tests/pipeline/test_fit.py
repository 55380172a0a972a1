"""Strain energy and the garment fit (service.pipeline.strain, service.pipeline.fit) on analytic fields."""

from __future__ import annotations

import numpy as np
import pytest

from service.geometry.mesh import vertex_normals
from service.pipeline.fields import FieldValues
from service.pipeline.fit import OWN_H, FitSettings, fit_garment, rows_of
from service.pipeline.strain import (
    RestShape,
    green_strain_norms,
    green_strain_norms_reference,
    strain_energy,
    strain_energy_reference,
)
from service.pipeline.untangle import GAP_DELTA, untangle_with_jacobian
from tests.meshes import grid_mesh


def _sheet(n=6, z=0.0, size=0.1):
    v, f = grid_mesh(n)
    return v * [size, size, 0] + [0, 0, z], f


def test_strain_gradient_matches_finite_differences():
    v, f = _sheet()
    rest = RestShape.build(v, f)
    rng = np.random.default_rng(0)
    x = v + rng.normal(scale=0.01, size=v.shape)
    _, g = strain_energy(x, rest)
    d = rng.normal(size=x.shape)
    eps = 1e-6
    fd = (strain_energy(x + eps * d, rest)[0] - strain_energy(x - eps * d, rest)[0]) / (2 * eps)
    assert fd == pytest.approx(float(np.sum(g * d)), rel=1e-6)


def test_strain_equals_its_reference_on_a_crumpled_garment_like_sheet():
    # Irregular rest triangles (Dm^-1 full, not the grid's) and large stretch and shear.
    rng = np.random.default_rng(1)
    v, f = _sheet(9)
    rest_v = v + rng.normal(scale=0.003, size=v.shape)
    rest = RestShape.build(rest_v, f)
    x = rest_v * [1.3, 0.8, 1] + rng.normal(scale=0.01, size=v.shape)
    e, g = strain_energy(x, rest)
    e_ref, g_ref = strain_energy_reference(x, rest)
    assert e == pytest.approx(e_ref, rel=1e-12)
    np.testing.assert_allclose(g, g_ref, rtol=1e-10, atol=1e-12 * np.abs(g_ref).max())
    norms, norms_ref = green_strain_norms(x, rest), green_strain_norms_reference(x, rest)
    np.testing.assert_allclose(norms, norms_ref, rtol=1e-12)
    assert e == pytest.approx(float(norms @ norms), rel=1e-12)  # the energy is the norms' squares summed
    # The rest matrices are the inverses of the rest edge matrices in the triangles' own 2-D frames:
    # Dm^-1 maps those edges to (1, 0) and (0, 1), so x = rest gives F^T F = I.
    assert strain_energy(rest_v, rest)[0] == pytest.approx(0, abs=1e-20)
    e1 = rest_v[f[:, 1]] - rest_v[f[:, 0]]
    np.testing.assert_allclose(np.linalg.norm(e1, axis=1) * rest.dm_inv[:, 0, 0], 1, rtol=1e-12)
    np.testing.assert_allclose(rest.dm_inv[:, 1, 0], 0)


def test_the_compiled_rest_shape_is_the_numpy_one_bit_for_bit():
    rng = np.random.default_rng(4)
    for n in (3, 9, 40):
        v, f = _sheet(n)
        v = v + rng.normal(scale=0.004, size=v.shape)
        a, b, c = f[-1]  # degenerate triangles, no strain term in either: two corners at one point,
        v[b] = v[a]
        a, b, c = f[len(f) // 2]  # and three corners on a line
        v[c] = 0.5 * (v[a] + v[b])
        fast, ref = RestShape.build(v, f), RestShape.build_reference(v, f)
        np.testing.assert_array_equal(fast.dm_inv, ref.dm_inv)
        np.testing.assert_array_equal(fast.faces, ref.faces)
        assert (ref.dm_inv[:, 0, 0] == 0).sum() >= 2


def test_strain_is_zero_at_rest_and_under_rigid_motion_and_matches_a_stretch():
    v, f = _sheet()
    rest = RestShape.build(v, f)
    c, s = np.cos(0.7), np.sin(0.7)
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    for x in (v, v @ rot.T + [0.3, -1, 2]):
        e, g = strain_energy(x, rest)
        # round-off: coordinates ~1 m over edges of 1.7 cm leave E ~ 1e-14 and gradients ~ 1e-12
        assert e == pytest.approx(0, abs=1e-20) and np.abs(g).max() < 1e-10
    # Uniaxial stretch by 1 + s along x: E = diag((1+s)^2 - 1, 0) / 2 on every triangle.
    stretched = v * [1.1, 1, 1]
    norms = green_strain_norms(stretched, rest)
    np.testing.assert_allclose(norms, 0.5 * (1.1**2 - 1), rtol=1e-12)


def planes(offsets: list[float]):
    """Layer k's fields: f = z - offsets[k] (flat surfaces facing +z), always active."""

    def fields(k, x, gradient):
        f = x[:, 2] - offsets[k]
        h = np.full(len(x), -1.0)
        if not gradient:
            return FieldValues(f, h, None, None)
        return FieldValues(f, h, np.tile([0.0, 0, 1], (len(x), 1)), np.zeros_like(x))

    return fields


reference = rows_of(untangle_with_jacobian)


def test_fit_pushes_a_garment_out_of_the_body_to_the_gap():
    v, f = _sheet(z=0.002)  # 2 mm outside the body surface z = 0: inside the 4 mm gap
    res = fit_garment(v, f, 1, 2, planes([0.0, 0.002]), reference)
    np.testing.assert_allclose(res.vertices[:, 2], GAP_DELTA, atol=1e-6)
    np.testing.assert_allclose(res.vertices[:, :2], v[:, :2], atol=1e-9)
    assert res.residual_before == pytest.approx(0.002) and res.residual_after < 1e-6


def test_fit_orders_two_crossing_garments_delta_apart():
    # Garment 1 (inner) at z = 10 mm, garment 2 (outer) at 8 mm: crossed. Each fits alone against
    # the others' fields; the exact operator splits the 6 mm violation evenly: 7 mm and 11 mm.
    offsets = [0.0, 0.010, 0.008]
    inner = fit_garment(*_sheet(z=0.010), 1, 3, planes(offsets), reference)
    outer = fit_garment(*_sheet(z=0.008), 2, 3, planes(offsets), reference)
    np.testing.assert_allclose(inner.vertices[:, 2], 0.007, atol=1e-6)
    np.testing.assert_allclose(outer.vertices[:, 2], 0.011, atol=1e-6)
    assert outer.vertices[:, 2].min() - inner.vertices[:, 2].max() == pytest.approx(GAP_DELTA, abs=2e-6)


def test_untangled_garment_is_left_alone():
    v, f = _sheet(z=0.02)
    res = fit_garment(v, f, 1, 2, planes([0.0, 0.02]), reference, FitSettings())
    assert res.linearisations == 0 and not res.optimised.any()
    np.testing.assert_array_equal(res.vertices, v)


def test_only_conflicting_vertices_and_their_rings_move():
    # The body bulges 18 mm up under one corner of a sheet 20 mm above it: only there is the sheet
    # closer than the 4 mm gap.
    v, f = _sheet(n=10, z=0.02)
    flat = planes([0.0, 0.02])

    def bump(x):
        return 0.018 * np.exp(-(x[:, 0] ** 2 + x[:, 1] ** 2) / 0.02**2)

    def fields(k, x, gradient):
        out = flat(k, x, gradient)
        if k != 0:
            return out
        b = bump(x)
        grad = None
        if gradient:
            grad = out.grad_f.copy()
            grad[:, :2] = 2 * b[:, None] * x[:, :2] / 0.02**2
        return FieldValues(out.f - b, out.h, grad, out.grad_h)

    res = fit_garment(v, f, 1, 2, fields, reference, FitSettings())
    assert 0 < res.optimised.sum() < 30
    np.testing.assert_array_equal(res.vertices[~res.optimised], v[~res.optimised])
    clearance = res.vertices[:, 2] - bump(res.vertices)
    assert clearance.min() > GAP_DELTA - FitSettings().conflict_tol
    assert res.residual_after <= FitSettings().conflict_tol


def test_a_nan_from_a_field_leaves_the_garment_finite_and_flags_the_fit():
    v, f = _sheet(z=0.002)  # inside the gap: the fit has work to do
    flat = planes([0.0, 0.002])

    def broken(k, x, gradient):
        out = flat(k, x, gradient)
        if k == 0:  # the body's network answers NaN for half of the points
            nan = np.where(np.arange(len(x)) % 2 == 0, np.nan, 0.0)
            grad = None if out.grad_f is None else out.grad_f + nan[:, None]
            return FieldValues(out.f + nan, out.h, grad, out.grad_h)
        return out

    res = fit_garment(v, f, 1, 2, broken, reference)
    assert np.all(np.isfinite(res.vertices))
    assert not res.ok  # flagged: make_outfit then serves the explicit mesh and names it in "fallback"


def test_degenerate_triangles_do_not_break_the_fit():
    v, f = _sheet(z=0.002)
    v = v.copy()
    v[f[0, 1]] = v[f[0, 0]]  # one triangle collapses to a segment: no rest frame, no strain term
    res = fit_garment(v, f, 1, 2, planes([0.0, 0.002]), reference)
    assert res.ok and np.all(np.isfinite(res.vertices))
    np.testing.assert_allclose(res.vertices[:, 2], GAP_DELTA, atol=1e-6)


def test_compact_strain_equals_the_full_mesh_strain_on_its_vertices():
    v, f = _sheet(n=8)
    rng = np.random.default_rng(1)
    x = v + rng.normal(scale=0.005, size=v.shape)
    part = RestShape.build(v, f).subset(np.arange(len(f)) % 3 == 0)
    keep = np.array([0, len(v) - 1])  # vertices of no chosen triangle still get a slot
    used, local = part.compact(keep)
    assert set(keep) <= set(used)
    e_full, g_full = strain_energy(x, part)
    e_local, g_local = strain_energy(x[used], local)
    assert e_local == pytest.approx(e_full, rel=1e-12)
    np.testing.assert_allclose(g_local, g_full[used], rtol=1e-12, atol=1e-15)
    assert np.all(np.delete(g_full, used, axis=0) == 0)
    used_ref, local_ref = part.compact_reference(keep)
    np.testing.assert_array_equal(used, used_ref)
    np.testing.assert_array_equal(local.faces, local_ref.faces)


def test_far_layers_are_never_asked_for_gradients_and_do_not_change_the_fit():
    # A third layer 0.5 m away from the sheet takes no part: its gradient graph is never run, and the
    # fit is the one of the sheet against the body alone.
    v, f = _sheet(z=0.002)
    asked = []
    flat3, flat2 = planes([0.0, 0.002, 0.5]), planes([0.0, 0.002])

    def fields(k, x, gradient):
        if gradient:
            asked.append((k, len(x)))
        return flat3(k, x, gradient)

    with_far = fit_garment(v, f, 1, 3, fields, reference)
    alone = fit_garment(v, f, 1, 2, flat2, reference)
    assert asked and all(k != 2 for k, _ in asked)
    np.testing.assert_allclose(with_far.vertices, alone.vertices, atol=1e-12)


@pytest.mark.parametrize("refresh", ["linear", "fields"])
def test_a_layer_the_bounds_put_far_is_never_asked_and_the_fit_is_the_same(refresh):
    """Where ``bounds`` put a layer ``FAR_FIELD`` away, its field is not asked (values or gradients),
    the fit returns the bound and ``INACTIVE`` there, and the fit is the one that asked everywhere
    (the layer is beyond ``reach`` either way); where they do not, it is asked."""
    from service.pipeline.fit import FAR_FIELD, INACTIVE

    v, f = _sheet(z=0.002)
    flat3 = planes([0.0, 0.002, 0.5])
    asked = []

    def fields(k, x, gradient):
        asked.append((k, len(x)))
        return flat3(k, x, gradient)

    bounds = np.zeros((len(v), 3))
    far = np.arange(len(v)) % 3 > 0  # two thirds of the vertices know layer 2 is far
    bounds[far, 2] = FAR_FIELD + 0.01
    settings = FitSettings(refresh=refresh)
    res = fit_garment(v, f, 1, 3, fields, reference, settings, bounds=bounds)
    with_bounds, asked[:] = list(asked), []
    every = fit_garment(v, f, 1, 3, fields, reference, settings)
    np.testing.assert_array_equal(res.vertices, every.vertices)
    # Before and after the step (a layer beyond reach is asked again either way), at the vertices not
    # known far only.
    assert [n for k, n in with_bounds if k == 2] == [(~far).sum()] * 2
    assert [n for k, n in asked if k == 2] == [len(v)] * 2
    moved = np.linalg.norm(res.vertices - v, axis=1)  # a bound holds less how far the vertex moved
    assert moved[far].max() > 0.001
    np.testing.assert_allclose(res.values[0][far, 2], FAR_FIELD + 0.01 - moved[far], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(res.values[1][far, 2], INACTIVE)
    np.testing.assert_array_equal(res.values[0][~far], every.values[0][~far])
    with pytest.raises(ValueError, match="reach"):
        fit_garment(v, f, 1, 3, fields, reference, FitSettings(reach=FAR_FIELD), bounds)


def test_the_values_a_fit_returns_are_the_fields_at_its_vertices():
    # The squeeze and the repair reuse them instead of evaluating the networks again.
    v, f = _sheet(n=8, z=0.009)
    fields = planes([0.0, 0.010, 0.008])
    res = fit_garment(v, f, 2, 3, fields, reference)
    assert res.ok and res.optimised.any()
    for k in (0, 1):
        now = fields(k, res.vertices, False)
        np.testing.assert_allclose(res.values[0][:, k], now.f, atol=1e-15)
        np.testing.assert_array_equal(res.values[1][:, k], now.h)
    # The garment's own layer from its explicit mesh: the distance to the tangent plane at each vertex
    # (the sheet's +z normal); active everywhere.
    normals = vertex_normals(v, f)
    np.testing.assert_allclose(np.abs(normals[:, 2]), 1)
    own = np.einsum("nd,nd->n", normals, res.vertices - v)
    np.testing.assert_allclose(res.values[0][:, 2], own, atol=1e-15)
    np.testing.assert_array_equal(res.values[1][:, 2], OWN_H)
    # With the network's own field, that column is the field's too.
    res = fit_garment(v, f, 2, 3, fields, reference, FitSettings(own_field="network"))
    np.testing.assert_allclose(res.values[0][:, 2], fields(2, res.vertices, False).f, atol=1e-15)


def test_the_linear_values_are_the_fields_to_second_order_in_the_step():
    """``refresh="linear"`` returns the same vertices as asking the fields again, and values that differ
    from theirs by no more than the fields' curvature allows: over a ball of radius R (f = |x| - R,
    curvature 1 / |x| <= 1 / R), by at most |d|^2 / (2 R) for a step d."""
    radius = 0.1
    v, f = _sheet(n=8, z=radius + 0.002, size=0.06)  # a flat sheet 2 mm over the top of the ball

    def fields(k, x, gradient):
        if k != 0:
            return planes([0.0, radius + 0.002])(k, x, gradient)
        r = np.linalg.norm(x, axis=1)
        h = np.full(len(x), -1.0)
        if not gradient:
            return FieldValues(r - radius, h, None, None)
        return FieldValues(r - radius, h, x / r[:, None], np.zeros_like(x))

    lin = fit_garment(v, f, 1, 2, fields, reference, FitSettings(refresh="linear"))
    ref = fit_garment(v, f, 1, 2, fields, reference, FitSettings(refresh="fields"))
    np.testing.assert_array_equal(lin.vertices, ref.vertices)
    step = np.linalg.norm(lin.vertices - v, axis=1)
    assert step.max() > 0.001  # the fit moved them, along the ball's normal and across it
    gap = np.abs(lin.values[0][:, 0] - ref.values[0][:, 0])
    assert 0 < gap.max() <= (step**2).max() / (2 * radius)
    np.testing.assert_array_less(gap, step**2 / (2 * radius) + 1e-15)
    np.testing.assert_array_equal(lin.values[1], ref.values[1])
    assert abs(lin.residual_after - ref.residual_after) <= (step**2).max() / (2 * radius)


def test_the_own_field_from_the_mesh_is_the_distance_to_the_tangent_plane_and_never_runs_its_network():
    # A curved sheet (a cylinder patch of radius 5 cm, like a sleeve): the own values at vertices moved
    # along their normals by s are s; moved along the surface, 0; the own layer's gradient is never asked.
    v, f = _sheet(n=8)
    radius = 0.05
    angle = v[:, 0] / radius
    v = np.stack([radius * np.sin(angle), v[:, 1], radius * np.cos(angle)], axis=1)
    normals = vertex_normals(v, f)
    from service.pipeline.fit import OwnField

    own = OwnField(v, normals, np.full(len(v), OWN_H))
    idx = np.arange(len(v))
    out = own.at(idx, v + 0.003 * normals)
    np.testing.assert_allclose(out.f, 0.003, rtol=1e-12)
    tangent = np.cross(normals, [0.0, 1.0, 0.0])
    np.testing.assert_allclose(own.at(idx, v + 0.003 * tangent).f, 0, atol=1e-15)
    np.testing.assert_array_equal(out.grad_f, normals)
    assert np.all(out.grad_h == 0) and np.all(out.h == OWN_H)
    asked = []
    flat = planes([-1.0, 0.04, 0.05])

    def fields(k, x, gradient):
        asked.append((k, gradient))
        return flat(k, x, gradient)

    res = fit_garment(v, f, 2, 3, fields, reference)
    assert res.ok and res.optimised.any()
    assert all(k != 2 for k, _ in asked) and (1, True) in asked


def test_rows_of_slices_the_full_jacobian():
    rng = np.random.default_rng(4)
    f, h = rng.normal(scale=0.01, size=(50, 3)), -np.ones((50, 3))
    full = untangle_with_jacobian(f, h)[1]
    for k in range(3):
        values, row = reference(f, h, True, row=k)
        np.testing.assert_array_equal(row, full[:, k : k + 1])
        np.testing.assert_array_equal(values, untangle_with_jacobian(f, h)[0])
    assert reference(f, h, False, row=1)[1] is None and reference(f, h, True)[1].shape == (50, 3, 6)


def test_fit_through_the_neural_row_graph_equals_the_full_jacobian_fit():
    """The fit asks the neural operator for its garment's row of the Jacobian only: the same fit as
    with the whole Jacobian, to float32 rounding (the rows differ by < 1e-3 where entries reach 1e3)."""
    pytest.importorskip("onnxruntime")
    from service.pipeline.untangle_onnx import NeuralUntangler

    neural = NeuralUntangler(threads=1)
    calls = []

    def by_row(f_star, h_star, jacobian, row=None):
        calls.append(row)
        out = neural(f_star, h_star, jacobian, row=row)
        return out.f, out.jacobian

    full = rows_of(lambda f_star, h_star, jacobian: tuple(neural(f_star, h_star, jacobian)))
    fields = planes([0.0, 0.010, 0.008])
    for layer, z in ((1, 0.010), (2, 0.008)):
        v, f = _sheet(n=8, z=z)
        ours, theirs = fit_garment(v, f, layer, 3, fields, by_row), fit_garment(v, f, layer, 3, fields, full)
        assert ours.ok and ours.linearisations == 1 and layer in calls
        np.testing.assert_array_equal(ours.optimised, theirs.optimised)
        np.testing.assert_allclose(ours.vertices, theirs.vertices, rtol=0, atol=1e-7)


def test_grad_h_is_asked_only_inside_the_untanglers_band_and_the_fit_is_the_same():
    """An untangler whose h-derivative is 0 outside |h*| < h_band (``Untangler.h_band``): the fit asks
    every near point for grad f alone ("f"), the points inside the band also for grad h, and fits as
    with grad h asked everywhere, bit for bit."""
    v, f = _sheet(n=10, z=0.009)
    band = 0.01

    def fields(k, x, gradient):
        base = planes([0.0, 0.010, 0.008])(k, x, gradient)
        h = np.where(k == 1, x[:, 0] - 0.05, -1.0)  # layer 1's opening crosses the sheet at x = 5 cm
        grad_h = None if not gradient else np.tile([1.0 if k == 1 else 0.0, 0, 0], (len(x), 1))
        return base._replace(
            h=h, grad_h=grad_h if gradient is True else (None if not gradient else 0 * grad_h)
        )

    def banded(f_star, h_star, jacobian, row=None):
        out, jac = reference(f_star, h_star, jacobian, row)
        if jac is not None:  # an h-derivative inside the band, like the neural operator's blend
            n = f_star.shape[1]
            jac = jac.copy()
            jac[:, :, n:] = np.where(np.abs(h_star) < band, 0.3, 0.0)[:, None, :]
        return out, jac

    asked = []

    def recording(k, x, gradient):
        asked.append((k, gradient, x.copy()))
        return fields(k, x, gradient)

    plain = fit_garment(v, f, 2, 3, fields, banded)
    banded.h_band = band
    ours = fit_garment(v, f, 2, 3, recording, banded)
    assert ours.ok and ours.optimised.any()
    np.testing.assert_array_equal(ours.vertices, plain.vertices)
    full_h = [x for k, g, x in asked if k == 1 and g is True]
    assert any(g == "f" for k, g, _ in asked if k == 1) and full_h
    assert all(np.all(np.abs(x[:, 0] - 0.05) < band) for x in full_h)  # only inside the band
