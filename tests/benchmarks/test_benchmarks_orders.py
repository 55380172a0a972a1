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
    assert set(m) == {"pairs", "penetration", "strain_p99", "strain_max", "ms", "clean"}
    assert m["clean"] == (m["pairs"] == 0 and m["penetration"] <= PENETRATION_LIMIT)
    assert 0 <= m["strain_p99"] <= m["strain_max"] < 1  # a T-shirt on a middle body stretches by percents
    # the strain is the returned mesh's against the catalog's: at rest, 0
    g = models.catalog["tshirt"]
    assert green_strain_norms(g.vertices, RestShape.build(g.vertices, g.faces)).max() < 1e-12
    _table("probe", [(["tshirt"], beta, m), (["tshirt"], beta, m | {"pairs": 3, "clean": False})])
    lines = capsys.readouterr().out.strip().splitlines()
    summary = [c.strip() for c in lines[-1].strip("|").split("|")]
    assert summary[:5] == ["2", "2", "0", str(int(m["clean"])), "3"]
