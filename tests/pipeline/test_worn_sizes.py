"""Garments worn in sizes and the tension map (issue 56), on the committed models: a size is its cut,
tight on a body bigger than its chart and loose on a smaller one; the map and the report say so."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from service.pipeline.body import DEFAULT_BETA
from service.pipeline.catalog import load_catalog
from service.pipeline.gltf import GltfLayer, outfit_glb
from service.pipeline.tension import MAP_STRETCH, CutShapes, tension_colors, vertex_strain
from service.pipeline.tryon import InvalidField, ModelEngine, OutfitSpec
from service.process.paths import models_dir


@pytest.fixture(scope="module")
def engine() -> ModelEngine:
    return ModelEngine.load(models_dir(), threads=1)


def chart_request(run: str, letter: str) -> dict:
    charts = json.loads((models_dir() / "garments" / "size_charts.json").read_text())
    request = charts[f"{run}/{letter}"]["request"]
    return {k: request[k] for k in ("gender", "height_cm", "weight_kg", "chest_cm", "waist_cm", "hip_cm")}


def glb_json(glb: bytes) -> dict:
    length = struct.unpack_from("<I", glb, 12)[0]
    return json.loads(glb[20 : 20 + length])


def test_the_map_is_white_at_rest_and_red_at_full_strain():
    colors = tension_colors(np.array([-0.2, 0.0, MAP_STRETCH / 3, MAP_STRETCH, 2 * MAP_STRETCH]))
    assert np.allclose(colors[0], colors[1]) and np.all(colors[1] > 0.9)  # white, slack or at rest
    assert colors[2][2] < 0.3 < colors[2][1]  # yellow: no blue, green up
    assert np.allclose(colors[3], colors[4]) and colors[3][0] > 0.7 > colors[3][1]  # red
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    assert np.allclose(vertex_strain(np.array([0.1, 0.3]), faces, 5), [0.1, 0.2, 0.2, 0.3, 0.0])


def test_colors_go_into_the_plain_glb_only():
    v, f = np.eye(3), np.array([[0, 1, 2]])
    doc = glb_json(outfit_glb([GltfLayer("tshirt", v, f, colors=np.ones((3, 3)) * 0.5)]))
    primitive = doc["meshes"][0]["primitives"][0]
    assert "COLOR_0" in primitive["attributes"]
    assert doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] == [1.0, 1.0, 1.0, 1.0]
    with pytest.raises(ValueError, match="plain encoding only"):
        outfit_glb([GltfLayer("tshirt", v, f, colors=np.ones((3, 3)))], "quantized")


def test_the_one_size_cut_on_the_mean_body_is_the_template(engine: ModelEngine):
    tshirt = load_catalog()["tshirt"]
    mean = engine.models.body.vertices(np.asarray(DEFAULT_BETA))
    strain = CutShapes(engine.models).strain("tshirt", None, mean, tshirt.vertices)
    assert np.abs(strain).max() < 1e-6


def test_a_smaller_size_is_tighter_and_a_larger_looser(engine: ModelEngine):
    body = chart_request("men", "L")
    made = {}
    for size in ("S", "L", "XXL"):
        result = engine.make(OutfitSpec(("tshirt",), **body, sizes=(size,), tension=True))
        report = result.report
        assert report["sizes"] == {"tshirt": size} and report["collision_free"]
        node = next(n for n in glb_json(result.glb)["nodes"] if n["name"] == "tshirt")
        assert node["extras"] == {"size": size}
        made[size] = (report["tension"]["tshirt"], result.layers[1].vertices)
    stretch = {s: t["stretch_p50"] for s, (t, _) in made.items()}
    assert stretch["S"] > 0.02 > stretch["L"] > stretch["XXL"], stretch  # S: cut 16 cm under his chest
    assert made["S"][0]["stretched_share"] > 0.5 > made["L"][0]["stretched_share"]
    # The XXL stands further off the body than the S: its vertices further from their centre on average.
    spread = {s: np.linalg.norm(v - v.mean(axis=0), axis=1).mean() for s, (_, v) in made.items()}
    assert spread["XXL"] > spread["L"] > spread["S"], spread


def test_a_bad_size_names_the_sizes_there_are(engine: ModelEngine):
    with pytest.raises(InvalidField) as err:
        engine.validate(OutfitSpec(("pants", "tshirt"), sizes=(None, "XXXL")))
    assert err.value.field == "garments.1.size" and "XS, S, M, L, XL, XXL" in err.value.allowed
