"""benchmarks.orders' measured outfits and tables (issue 21's pairs and stacks)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("onnxruntime")


@pytest.fixture(scope="module")
def models():
    from service.pipeline.outfit import OutfitModels

    return OutfitModels.load(threads=1)


def test_a_measured_outfit_reports_what_the_summary_needs(models, capsys):
    from benchmarks.orders import PENETRATION_LIMIT, _table, measured
    from service.pipeline.strain import RestShape, green_strain_norms

    beta = np.array([0.5, 0.4, 0.5])
    m = measured(models, ["tshirt"], beta)
    assert set(m) == {"pairs", "reported", "penetration", "strain_p99", "strain_max", "ms", "clean"}
    assert m["pairs"] == m["reported"]  # the exact count and the report's agree on a single garment
    assert m["clean"] == (m["pairs"] == 0 and m["penetration"] <= PENETRATION_LIMIT)
    # alone on a middle body the fit and the repair move a T-shirt by millimetres: percents of strain
    assert 0 <= m["strain_p99"] <= m["strain_max"] < 0.2
    # the strain is against the explicit mesh on the same body: that mesh itself has none
    x = models.space.to_bodies([models.explicit["tshirt"].canonical(beta)], models.body.vertices(beta))[0]
    faces = models.catalog["tshirt"].faces
    assert green_strain_norms(x, RestShape.build(x, faces)).max() < 1e-12
    refused = measured(models, ["skirt", "shorts"], beta)
    assert set(refused) == {"refused"} and "shorts cannot be worn over skirt" in refused["refused"]
    runs = [(["tshirt"], beta, m), (["tshirt"], beta, m | {"pairs": 3, "reported": 1, "clean": False})]
    _table("probe", runs + [(["skirt", "shorts"], beta, refused)])
    lines = capsys.readouterr().out.strip().splitlines()
    assert any("refused: skirt wraps both legs" in line for line in lines)
    assert any("| 3 (report: 1) |" in line for line in lines)  # a disagreement is printed, not hidden
    summary = [c.strip() for c in lines[-1].strip("|").split("|")]
    assert summary[:5] == ["3", "2", "1", str(int(m["clean"])), "3"]


def test_the_junction_table_lists_the_catalog_pairs_with_a_run(models, capsys):
    from benchmarks.orders import junctions

    junctions(models)
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ") and " < " in line]
    cells = {r.split("|")[1].strip(): [c.strip() for c in r.strip("|").split("|")] for r in rows}
    assert cells["skirt < pants"][4] == "yes" and int(cells["skirt < pants"][2]) >= 30
    assert cells["jacket < tshirt"][1] == "arm + torso" and cells["jacket < tshirt"][4] == "no"
    # the drape's armhole hangs lower than the template's
    assert int(cells["jacket < tshirt"][3]) > int(cells["jacket < tshirt"][2]) > 0
    assert "tshirt < jacket" not in cells  # the usual order holds nothing apart


def test_the_let_down_table_takes_the_pairs_with_a_lowering_on_every_corner(models, monkeypatch, capsys):
    import argparse

    import benchmarks.orders as orders
    from benchmarks.imported import corners

    asked = []
    monkeypatch.setattr(orders, "measured", lambda m, ids, beta: asked.append((tuple(ids), tuple(beta))) or {
        "refused": "probe"})  # fmt: skip
    orders.let_down(models, argparse.Namespace(bodies=1))
    pairs = sorted({ids for ids, _ in asked})
    # orders against the grain whose inner junction hangs lower: the long sleeve and the jacket under
    # tighter tops, shorts under pants; never the usual way (a T-shirt under a jacket)
    assert ("jacket", "tank_top") in pairs and ("shorts", "pants") in pairs
    assert ("tshirt", "jacket") not in pairs and ("pants", "shorts") not in pairs
    assert all(models.pairs.lowering(*ids) is not None and not models.refusals(list(ids)) for ids in pairs)
    bodies = {beta for _, beta in asked}
    assert len(bodies) == 5 and {tuple(c) for c in corners()} <= bodies
    assert len(asked) == 5 * len(pairs)
    assert "Pairs let down at a junction" in capsys.readouterr().out


def test_the_refusal_rates_count_every_ordered_stack(capsys):
    # A catalog of four where a skirt under pants is refused: every ordered stack is asked, once.
    import itertools
    from types import SimpleNamespace

    from benchmarks.orders import refusal_rates

    catalog = {"pants": 0, "skirt": 0, "tshirt": 0, "jacket": 0}

    def refusals(ids):
        return ["no"] if "skirt" in ids and "pants" in ids[ids.index("skirt") + 1:] else []

    refusal_rates(SimpleNamespace(catalog=catalog, refusals=refusals))
    out = capsys.readouterr().out
    expected = []
    for size in (3, 4):
        stacks = list(itertools.permutations(catalog, size))
        refused = sum(bool(refusals(list(s))) for s in stacks)
        assert f"| {size} | {len(stacks)} | {refused} | {100 * refused / len(stacks):.1f} |" in out
        expected.append(refused / len(stacks))
    assert expected == [6 / 24, 12 / 24]  # both in a 3-stack: 6 of 24 orders; in a 4-stack: half
    assert f"expected share of --stacks refused: {100 * sum(expected) / 2:.1f} %" in out
