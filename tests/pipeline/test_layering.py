"""The layer-order rule: slices against hand-computed loops, the two rules on synthetic bodies built
from cylinders, the decisions on the committed catalog, and the 422 the service answers."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import trimesh

from service.pipeline.collisions import layering
from service.pipeline.collisions.layering import (
    BodySlices,
    GarmentProfile,
    LayeringRule,
    hull_perimeter,
    slice_loops,
)
from service.pipeline.collisions.settings import SETTINGS


def tube(radius: float, z0: float, z1: float, x: float = 0.0, sections: int = 48) -> trimesh.Trimesh:
    """An open cylinder (no caps) around the vertical line through (x, 0) from z0 to z1."""
    m = trimesh.creation.cylinder(radius, z1 - z0, sections=sections)
    m.apply_translation([x, 0.0, (z0 + z1) / 2])
    side = np.abs(m.face_normals[:, 2]) < 0.5
    m.update_faces(side)
    m.remove_unreferenced_vertices()
    return m


def closed(*parts: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.util.concatenate(parts)
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def test_a_slice_through_a_tube_is_one_closed_loop_of_its_perimeter():
    m = tube(0.1, 0.0, 1.0, sections=64)
    (loop,) = slice_loops(np.asarray(m.vertices), np.asarray(m.faces), 0.37)
    assert loop.closed
    assert loop.perimeter == pytest.approx(2 * 64 * 0.1 * np.sin(np.pi / 64), rel=1e-9)
    assert loop.contains(np.array([[0.0, 0.0], [0.05, 0.05], [0.2, 0.0]])).tolist() == [True, True, False]
    assert slice_loops(np.asarray(m.vertices), np.asarray(m.faces), 1.5) == []


def test_a_slice_of_an_open_strip_is_open():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], dtype=np.float64)
    (loop,) = slice_loops(v, np.array([[0, 1, 2], [0, 2, 3]]), 0.5)
    assert not loop.closed and loop.perimeter == pytest.approx(1.0)


def test_hull_perimeter_of_a_square_with_inner_points():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5], [0.2, 0.7]], dtype=np.float64)
    assert hull_perimeter(square) == pytest.approx(4.0)


@pytest.fixture(scope="module")
def legs_body() -> BodySlices:
    """Two legs (z 0-0.8) under a torso (z 0.8-1.4), both legs' tops closed into the torso."""
    torso = trimesh.creation.cylinder(0.17, 0.6, sections=48)
    torso.apply_translation([0, 0, 1.1])
    legs = [trimesh.creation.cylinder(0.07, 0.8, sections=32) for _ in range(2)]
    for leg, x in zip(legs, (-0.09, 0.09), strict=True):
        leg.apply_translation([x, 0, 0.4])
    return BodySlices.build(*closed(torso, *legs))


def profile(name, body, *parts) -> GarmentProfile:
    return GarmentProfile.build(name, *closed(*parts), body)


def test_pants_cannot_go_over_a_long_skirt_but_a_skirt_goes_over_pants(legs_body):
    pants = profile(
        "pants", legs_body, tube(0.18, 0.8, 1.05), tube(0.08, 0.1, 0.8, -0.09), tube(0.08, 0.1, 0.8, 0.09)
    )
    skirt = profile("skirt", legs_body, tube(0.22, 0.4, 1.05))
    mini = profile("mini", legs_body, tube(0.22, 0.77, 1.05))  # 3 cm below the crotch: pushed up
    profiles = {"pants": pants, "skirt": skirt, "mini": mini}
    (refusal,) = layering.refusals(profiles, ["skirt", "pants"], legs_body)
    assert (refusal.inner, refusal.outer) == ("skirt", "pants")
    assert "both legs" in refusal.reason and "40 cm" in refusal.reason
    assert layering.refusals(profiles, ["pants", "skirt"], legs_body) == []
    assert layering.refusals(profiles, ["mini", "pants"], legs_body) == []


def test_the_junction_run_is_how_far_a_crotch_hangs_below_the_other_one(legs_body):
    pants = profile(
        "pants", legs_body, tube(0.18, 0.8, 1.05), tube(0.08, 0.1, 0.8, -0.09), tube(0.08, 0.1, 0.8, 0.09)
    )
    mini = profile("mini", legs_body, tube(0.22, 0.77, 1.05))  # 3 cm below the crotch
    skirt = profile("skirt", legs_body, tube(0.22, 0.4, 1.05))
    run, top, parts = layering.junction_run(mini, pants, legs_body)
    assert run == 3 and 0.77 < legs_body.levels[top] < 0.8  # three 1 cm levels, just under the crotch
    assert {legs_body.names[top][i] for i in parts} == {"leg"} and len(parts) == 2
    assert layering.junction_run(skirt, pants, legs_body)[0] == 40
    assert layering.junction_run(pants, skirt, legs_body) is None  # a skirt over pants holds nothing apart


def test_an_outer_garment_too_small_to_stretch_over_the_body_is_refused(legs_body):
    leg = 2 * 32 * 0.07 * np.sin(np.pi / 32)  # the body's leg perimeter
    tight = 0.07 * 0.97 / (1 + SETTINGS.stretch_limit)  # stretched by the limit: 3 % short of the leg
    inner = profile("inner", legs_body, tube(0.075, 0.2, 0.6, -0.09))
    small = profile("small", legs_body, tube(tight, 0.3, 0.5, -0.09))
    fits = profile("fits", legs_body, tube(0.076, 0.3, 0.5, -0.09))
    profiles = {"inner": inner, "small": small, "fits": fits}
    (refusal,) = layering.refusals(profiles, ["inner", "small"], legs_body)
    assert (
        refusal.outer == "small"
        and f"needs {100 * (leg + 2 * np.pi * SETTINGS.margin):.0f} cm" in refusal.reason
    )
    assert layering.refusals(profiles, ["inner", "fits"], legs_body) == []


@pytest.fixture(scope="module")
def catalog_rule():
    from service.pipeline.body import DEFAULT_BETA, BodyModel
    from service.pipeline.catalog import load_catalog

    body = BodyModel.load()
    return LayeringRule(body.vertices(np.asarray(DEFAULT_BETA)), body.faces), dict(load_catalog())


def test_pants_and_shorts_hold_the_legs_apart_a_skirt_and_the_tops_do_not(catalog_rule):
    rule, catalog = catalog_rule
    assert {g for g, garment in catalog.items() if rule.holds_legs_apart(garment)} == {"pants", "shorts"}


def test_the_catalog_refuses_only_a_skirt_under_legged_bottoms(catalog_rule):
    rule, catalog = catalog_rule
    refused = {
        (a, b)
        for a, b in itertools.permutations(sorted(catalog), 2)
        if rule.refusals([catalog[a], catalog[b]])
    }
    assert refused == {("skirt", "pants"), ("skirt", "shorts")}


def test_the_service_names_the_refused_garments_and_why():
    pytest.importorskip("onnxruntime")
    from fastapi.testclient import TestClient

    from service.server.app import create_app
    from service.server.settings import Settings

    app = create_app(Settings(self_test_untangle=False, configure_logging=False))
    with TestClient(app) as client:
        assert app.state.tryon.wait_loaded(120), app.state.tryon.detail
        response = client.post("/v1/outfits", json={"garments": ["tank_top", "skirt", "pants"]})
        assert response.status_code == 422
        (error,) = response.json()["errors"]
        assert error["field"] == "garments"
        assert (
            "skirt wraps both legs" in error["message"]
            and "pants cannot be worn over skirt" in error["message"]
        )
        ok = client.post("/v1/outfits", json={"garments": ["pants", "skirt"], "options": {"untangle": False}})
        assert ok.status_code == 200, ok.text
        metrics = client.get("/metrics").text
        assert 'ulnef_outfit_rejected_total{reason="layer_order"} 1.0' in metrics
