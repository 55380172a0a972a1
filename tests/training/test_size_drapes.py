"""Drapes of a body in the sizes around its own (issue 56, ``training.drape.sizes``): which sizes, and
that a smaller size is cloth stretched over the body where a larger one is not."""

from __future__ import annotations

import json

import numpy as np
import pytest

from service.pipeline.body import DEFAULT_BETA
from service.pipeline.canonical import CanonicalSpace
from service.pipeline.catalog import load_catalog
from service.pipeline.ease import principal_strain
from service.pipeline.explicit import ExplicitModel
from service.pipeline.size_model import SizeModel
from service.pipeline.sizes import LETTERS, chart
from service.pipeline.strain import RestShape
from service.process.paths import models_dir
from training.drape.sizes import build, own_letter, size_window
from training.explicit_sizes import chart_sizes, errors_mm, fit_size_model, mean_cut, size_rows
from training.garments.grading import CHARTS_NAME, chart_builder, chart_vertices, graded_rest


def test_the_window_is_the_own_letter_and_its_neighbours():
    assert size_window("M") == ("S", "M", "L")
    assert size_window("XS") == ("XS", "S") and size_window("XXL") == ("XL", "XXL")
    m = next(r for r in chart("men") if r.letter == "M")
    assert own_letter("men", False, m.chest_cm + 1.0, 0.0) == "M"
    assert own_letter("men", True, 0.0, m.hip_cm - 1.0) == "M"  # a bottom goes by the hip


@pytest.mark.slow
def test_a_body_draped_in_three_sizes_is_stretched_most_in_the_smallest(tmp_path):
    build(tmp_path, 0, 1, ("tank_top",))
    with np.load(tmp_path / "test" / "000.npz") as z:
        arrays = {k: z[k] for k in z.files}
    sizes = sorted({k.split("/")[1] for k in arrays if k.startswith("tank_top/")}, key=LETTERS.index)
    assert len(sizes) == 3  # a woman of the middle: her letter and one either side
    builder, tank = chart_builder(), load_catalog()["tank_top"]
    space = CanonicalSpace.build(builder.model.vertices(np.asarray(DEFAULT_BETA)), builder.model.faces)
    charts = json.loads((models_dir() / "garments" / CHARTS_NAME).read_text())
    mean_strain = []
    for size in sizes:
        rest = graded_rest(space, tank.vertices, chart_vertices(builder, charts[f"women/{size}"]))
        strain = principal_strain(arrays[f"tank_top/{size}/world"], RestShape.build(rest, tank.faces))
        mean_strain.append(float(np.mean(strain)))
    assert mean_strain[0] > mean_strain[1] > mean_strain[2], mean_strain
    # The tiny training end to end: a size model fitted to these three drapes reproduces each closer than
    # the one-size garment does (the least squares includes no effect at all), and survives its file.
    explicit = ExplicitModel.load("tank_top")
    rows = size_rows(tmp_path, "test", tank, explicit, mean_cut(tank), chart_sizes(tank, charts))
    model = fit_size_model(tank, rows, mean_cut(tank), chart_sizes(tank, charts), explicit)
    sized, one = errors_mm(model, explicit, rows)
    assert np.all(sized < one), (sized, one)
    model.save(tmp_path / "explicit" / "tank_top.size.npz")
    explicit.save(tmp_path / "explicit" / "tank_top.npz")
    back = SizeModel.load("tank_top", tmp_path / "explicit")
    beta, delta = rows.beta[0], rows.delta[0]
    assert np.allclose(back.offset(beta, delta), model.offset(beta, delta), atol=1e-9)
