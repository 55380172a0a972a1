"""A dress (``tests/garment_files.py``: a strapless tube from under the arms to under the knees)
imported end to end with the tiny settings of ``test_garment_import``, then worn alone, under a bundled
top, over bundled bottoms: each outfit clean by the measures (no crossing triangle pairs, at most
``PENETRATION_LIMIT`` % of a garment's vertices inside another layer), and the orders cloth cannot
take (pants or shorts over the dress's skirt) refused, saying why. Nothing reads its category: what it
does comes from its geometry (``collisions.traits``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.orders import PENETRATION_LIMIT
from service.cli import main as ulnef
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.catalog import full_catalog, verified_imports
from tests.garment_files import dress_tube, write_obj
from tests.training.test_garment_import import TINY

pytestmark = pytest.mark.slow  # the import drapes ~2,300 vertices on 17 bodies: minutes on two cores


@pytest.fixture(scope="module")
def garments(tmp_path_factory) -> Path:
    """The garments directory after a tiny import of the dress's OBJ in cm, through the CLI."""
    body = BodyModel.load()
    floor = float(body.vertices(np.asarray(DEFAULT_BETA))[:, 2].min())
    root = tmp_path_factory.mktemp("dress")
    source = write_obj(root / "files", "dress", *dress_tube(body, edge=0.025), units="cm", floor=floor)
    out = root / "garments"
    code = ulnef(["garments", "import", str(source), "--id", "tube_dress", "--name", "Tube dress",
                  "--category", "dress", "--units", "cm", "--models", str(out), *TINY])  # fmt: skip
    assert code == 0
    return out


@pytest.fixture(scope="module")
def models(garments):
    from service.pipeline.outfit import OutfitModels

    return OutfitModels.load(threads=2, imported=verified_imports(garments)[0])


def _rule(models):
    """The layering rule on the models' mean body (``collisions.layering``), made once."""
    from service.pipeline.collisions.layering import LayeringRule

    if not hasattr(models, "_test_rule"):
        models._test_rule = LayeringRule(models.space.mean_vertices, models.space.faces)
    return models._test_rule


def test_the_dress_is_imported_with_its_top_and_hem(garments):
    dress = full_catalog(None, garments)["tube_dress"]
    assert dress.category == "dress" and sorted(dress.openings) == ["hem", "top"]
    v = dress.vertices
    assert v[dress.openings["top"], 2].mean() > v[dress.openings["hem"], 2].mean()


def test_its_traits_come_from_its_geometry(models):
    from service.pipeline.collisions.traits import traits_of, tucked, worn_alike

    rule, catalog = _rule(models), models.catalog
    t = traits_of(rule, catalog["tube_dress"])
    assert t.covers_chest and t.hangs_free_below_hips and not t.holds_legs_apart and not t.has_sleeves
    jacket, pants = traits_of(rule, catalog["jacket"]), traits_of(rule, catalog["pants"])
    assert worn_alike(t, jacket) and not tucked(jacket, t)  # worn like a top: nothing tucked into it
    assert tucked(t, pants)  # pants over it would have it tucked in, as a top, but:


def test_the_dress_stays_where_it_is_worn(models):
    # Its top edge is held as a boned bodice holds it (``training.drape.dataset.PINNED_OPENINGS``):
    # unpinned, the drape let it slide 44 cm down to the hips.
    dress = models.catalog["tube_dress"]
    drape = models.explicit["tube_dress"].canonical(np.asarray(DEFAULT_BETA, dtype=np.float64))
    for opening in ("top", "hem"):
        rest = dress.vertices[dress.openings[opening], 2].mean()
        assert abs(drape[dress.openings[opening], 2].mean() - rest) < 0.03, opening


@pytest.mark.parametrize("outer", ["pants", "shorts"])
def test_legged_bottoms_over_the_dress_are_refused(models, outer):
    (refusal,) = _rule(models).refusals([models.catalog[g] for g in ("tube_dress", outer)])
    assert (refusal.inner, refusal.outer) == ("tube_dress", outer)
    assert "wraps both legs in one piece" in refusal.reason and "cannot be worn over" in refusal.reason


OUTFITS = [
    ["tube_dress"],
    ["tube_dress", "jacket"],  # a top over it
    ["tube_dress", "tshirt"],
    ["pants", "tube_dress"],  # a bottom under it: its skirt hangs free over the legs
    ["tank_top", "shorts", "tube_dress", "jacket"],
]


@pytest.mark.parametrize("ids", OUTFITS, ids=["<".join(getattr(o, "values", [o])[0]) for o in OUTFITS])
def test_the_dress_alone_and_layered_is_clean(models, ids):
    from service.pipeline.outfit import make_outfit
    from training.drape.dataset import sample_betas

    assert _rule(models).refusals([models.catalog[g] for g in ids]) == []
    beta = sample_betas(1, 3)[0]  # a held-out body
    r = make_outfit(models, ids, beta, measure=True).report
    assert r["crossing_pairs"] == 0 and sum(r["intersections_after"].values()) == 0, r["intersections_after"]
    assert max(r["penetration_after"].values()) <= PENETRATION_LIMIT / 100, r["penetration_after"]
