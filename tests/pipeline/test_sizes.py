"""Size charts, ease by region and the size rule (issue 56): ``service.pipeline.sizes``, ``ease`` and
``sizing``, on shapes whose answers are known in closed form, then on the committed charts."""

from __future__ import annotations

import json

import numpy as np
import pytest

from service.pipeline import ease as E
from service.pipeline.sizes import BANDS, FWF, LETTERS, RUNS, chart, letter_of
from service.pipeline.sizing import CLOSE_CM, EASE_TOLERANCE_CM, SIZES_NAME, recommend
from service.pipeline.strain import RestShape
from service.process.paths import models_dir


@pytest.mark.parametrize("run", RUNS)
def test_a_chart_row_is_its_band_centre_and_grows_with_the_size(run):
    rows = chart(run)
    assert tuple(r.letter for r in rows) == LETTERS
    for row, (lo, hi) in zip(rows, BANDS[run], strict=True):
        assert row.chest_cm == (lo + hi) / 2
        assert letter_of(run, row.chest_cm) == row.letter
        fwf_chest = [r[0] for r in FWF[run]]
        assert row.extrapolated == (not fwf_chest[0] <= row.chest_cm <= fwf_chest[-1])
    for name in ("chest_cm", "waist_cm", "hip_cm"):
        values = [getattr(r, name) for r in rows]
        assert all(b > a for a, b in zip(values, values[1:], strict=False)), name
    assert letter_of(run, BANDS[run][0][0] - 0.1) is None
    assert letter_of(run, BANDS[run][-1][1]) is None


def test_fwf_rows_are_read_back_where_the_chart_centre_meets_one():
    # The men's M centre, chest 98, lies between FWF's 48 (96/86/98/174) and 50 (100/90/102/177).
    m = next(r for r in chart("men") if r.letter == "M")
    assert (m.waist_cm, m.hip_cm, m.height_cm) == (88.0, 100.0, 175.5)


def _tube(radius: float, z0: float, z1: float, n: int = 96, rings: int = 12, centre=(0.0, 0.0)):
    """An open tube ``(V, 3)``, ``(F, 3)`` round the z axis through ``centre``."""
    angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
    zs = np.linspace(z0, z1, rings)
    v = np.array([[centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a), z]
                  for z in zs for a in angles])  # fmt: skip
    faces = []
    for k in range(rings - 1):
        for i in range(n):
            a, b = k * n + i, k * n + (i + 1) % n
            faces += [[a, b, b + n], [a, b + n, a + n]]
    return v, np.array(faces)


def _closed_cylinder(radius: float, z0: float, z1: float, n: int = 96):
    v, f = _tube(radius, z0, z1, n, rings=2)
    bottom, top = len(v), len(v) + 1
    v = np.vstack([v, [[0, 0, z0], [0, 0, z1]]])
    caps = [[bottom, (i + 1) % n, i] for i in range(n)] + [[top, n + i, n + (i + 1) % n] for i in range(n)]
    return v, np.vstack([f, caps])


def test_a_tube_round_a_cylinder_has_the_ease_of_its_offset():
    body_v, body_f = _closed_cylinder(0.15, -0.5, 0.5)
    plane = E.Plane.through(np.zeros(3), np.array([0.0, 0.0, 1.0]))
    section = E.body_section(body_v, body_f, plane, np.zeros(2))
    n = 96
    polygon = 2 * n * 0.15 * np.sin(np.pi / n)  # the body's section is a regular 96-gon
    assert E.tape_cm(section.tape) == pytest.approx(100 * polygon, rel=1e-9)
    for offset in (0.005, 0.02):
        v, f = _tube(0.15 + offset, -0.3, 0.3)
        parts = np.array(["torso"] * len(f), dtype=object)
        cut = E.garment_section(v, f, parts, plane, section)
        ease = E.tape_cm(cut) - E.tape_cm(section.tape)
        assert ease == pytest.approx(100 * 2 * n * offset * np.sin(np.pi / n), rel=1e-6)
    # Faces of an arm are not the torso's section; half a tube does not go round it.
    arm = np.array(["upperarm_l"] * len(f), dtype=object)
    assert E.garment_section(v, f, arm, plane, section) is None
    half = f[v[f].mean(axis=1)[:, 0] > 0]
    assert E.garment_section(v, half, parts[: len(half)], plane, section) is None
    # A tube ending above the plane does not reach it.
    above, f_above = _tube(0.17, 0.05, 0.3)
    assert E.garment_section(above, f_above, parts, plane, section) is None


def test_a_limb_section_keeps_the_loop_round_its_own_limb():
    # Two legs side by side, a trouser leg round each: the left leg's thigh sees only its own.
    left_v, left_f = _closed_cylinder(0.08, -0.5, 0.5)
    right_v, right_f = _closed_cylinder(0.08, -0.5, 0.5)
    right_v = right_v + [0.2, 0.0, 0.0]
    body_v, body_f = np.vstack([left_v, right_v]), np.vstack([left_f, right_f + len(left_v)])
    plane = E.Plane.through(np.zeros(3), np.array([0.0, 0.0, 1.0]), limb=True)
    section = E.body_section(body_v, body_f, plane, np.zeros(2))
    a, fa = _tube(0.09, -0.3, 0.3)
    b, fb = _tube(0.09, -0.3, 0.3, centre=(0.2, 0.0))
    v, f = np.vstack([a, b]), np.vstack([fa, fb + len(a)])
    cut = E.garment_section(v, f, np.array(["upperleg_l"] * len(f), dtype=object), plane, section)
    assert E.tape_cm(cut) - E.tape_cm(section.tape) == pytest.approx(100 * 2 * np.pi * 0.01, rel=2e-3)


def test_principal_strain_of_known_deformations():
    v, f = _tube(0.1, 0.0, 0.3)
    rest = RestShape.build(v, f)
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(E.principal_strain(v @ rotation.T + 1.0, rest), 0.0, atol=1e-12)
    stretched = v * [1.0, 1.0, 1.2]  # 20 % along the tube, nothing round it
    np.testing.assert_allclose(E.principal_strain(stretched, rest), 0.2, atol=1e-9)
    shrunk = v * 0.9  # 10 % shorter every way: the largest stretch is -10 %
    np.testing.assert_allclose(E.principal_strain(shrunk, rest), -0.1, atol=1e-9)


def _eases(under: float, design: float = 8.0, step: float = 8.0, first: float = 82.0) -> dict:
    """Chest ease of six sizes ``step`` apart on a body of girth ``under``."""
    return {s: {"chest": first + design + k * step - under} for k, s in enumerate(LETTERS)}


def test_a_body_at_a_sizes_centre_gets_that_size_and_one_a_size_apart_the_next():
    design = {"chest": 8.0}
    for k, letter in enumerate(LETTERS):
        chest = 82.0 + 8.0 * k
        assert recommend(_eases(chest), design).size == letter
        # Anywhere in its band (up to half a step above the centre) still that size.
        assert recommend(_eases(chest + EASE_TOLERANCE_CM - 0.01), design).size == letter


def test_too_big_a_body_gets_the_largest_size_marked_not_fitting():
    got = recommend(_eases(82.0 + 8.0 * 7), {"chest": 8.0})
    assert (got.size, got.fits, got.short) == ("XXL", False, ("chest",))


def test_the_runner_up_is_the_neighbour_a_close_fit_or_miss_points_to():
    design = {"chest": 8.0}
    m = 82.0 + 16.0
    roomier = recommend(_eases(m + EASE_TOLERANCE_CM - CLOSE_CM / 2), design)
    assert (roomier.size, roomier.runner_up, roomier.runner_up_is) == ("M", "L", "roomier")
    closer = recommend(_eases(m - 8.0 + EASE_TOLERANCE_CM + CLOSE_CM / 2), design)
    assert (closer.size, closer.runner_up, closer.runner_up_is) == ("M", "S", "closer")
    assert recommend(_eases(m), design).runner_up is None


# ---------------------------------------------------------------- the committed grading


@pytest.fixture(scope="module")
def sizes() -> dict:
    return json.loads((models_dir() / "garments" / SIZES_NAME).read_text())


def test_each_chart_body_is_recommended_its_own_size_for_every_style(sizes):
    """A body at the centre of a chart size (the size's chart body: under it, each size's girth minus
    the ease it has there) is recommended that size, for every bundled style."""
    for style, entry in sizes["styles"].items():
        girths, chart_ease, design = entry["girths"], entry["chart_ease"], entry["design_ease"]
        for letter in LETTERS:
            under = {r: girths[letter][r] - chart_ease[letter][r] for r in chart_ease[letter]}
            eases = {s: {r: girths[s][r] - under[r] for r in girths[s] if r in under} for s in LETTERS}
            assert recommend(eases, design).size == letter, (style, letter)


def test_a_styles_ease_is_its_design_ease_at_every_size(sizes):
    """Grading keeps the pattern's ease: each size on its chart body within half a chart step of M's."""
    for style, entry in sizes["styles"].items():
        for letter, eases in entry["chart_ease"].items():
            for region, ease in eases.items():
                assert abs(ease - entry["design_ease"][region]) < EASE_TOLERANCE_CM, (style, letter, region)


def test_every_chart_body_measures_its_row():
    """The committed chart bodies (``python -m training.garments.grading``) reproduce their rows as
    issue 55 reproduces a shopper's: height within 0.5 cm, each girth within 1 cm."""
    charts = json.loads((models_dir() / "garments" / "size_charts.json").read_text())
    assert set(charts) == {f"{run}/{letter}" for run in RUNS for letter in LETTERS}
    for key, record in charts.items():
        row, body = record["row"], record["body"]
        assert abs(body["height_cm"] - row["height_cm"]) <= 0.5, key
        for name in ("chest_cm", "waist_cm", "hip_cm"):
            assert abs(body[name] - row[name]) <= 1.0, (key, name)
        assert body["predicted"] == []


def test_a_chart_body_is_built_again_from_its_request():
    from service.pipeline.body_build import BodyRequest
    from training.garments.grading import chart_builder

    record = json.loads((models_dir() / "garments" / "size_charts.json").read_text())["men/M"]
    built = chart_builder().build(BodyRequest(**record["request"]))
    report = built.report()
    for name in ("height_cm", "weight_kg", "chest_cm", "waist_cm", "hip_cm"):
        assert report[name] == pytest.approx(record["body"][name], abs=0.11), name
