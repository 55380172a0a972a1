"""The cells within a distance of a mesh (``service.geometry.occupancy``): never missing a box within
that distance of a triangle's box, and flagging none farther than the cells it grew by and one more."""

import numpy as np
import pytest
import trimesh

from service.geometry.occupancy import Occupancy, boxes_touching_reference, triangle_boxes


def _bent_sphere():
    s = trimesh.creation.icosphere(subdivisions=3, radius=0.2)
    v = np.asarray(s.vertices)
    return v * np.array([1.6, 0.7, 1.0]) + 0.05 * np.sin(8 * v[:, [1, 2, 0]]), np.asarray(s.faces)


@pytest.mark.parametrize("pad", [0.004, 0.015, 0.05])
def test_touching_holds_every_box_within_pad_and_none_past_its_cells(pad):
    v, f = _bent_sphere()
    occupancy = Occupancy.build(v, f, pad)
    assert occupancy.cell >= pad
    rng = np.random.default_rng(3)
    centre = rng.normal(scale=0.3, size=(4000, 3))
    half = rng.uniform(0.0, 0.03, size=(4000, 1)) * rng.uniform(0.2, 1.0, size=(4000, 3))
    lo, hi = centre - half, centre + half
    got = occupancy.touching(lo, hi)
    within = boxes_touching_reference(v, f, lo - pad, hi + pad)
    slack = (np.ceil(pad / occupancy.cell) + 1) * occupancy.cell * (1 + 1e-9)
    beyond = ~boxes_touching_reference(v, f, lo - slack, hi + slack)
    assert within.any() and (~within).any()
    assert got[within].all()  # never misses one
    assert not got[beyond].any()  # nor flags one past a cell more


def test_the_compiled_boxes_are_numpys():
    v, f = _bent_sphere()
    lo, hi = triangle_boxes(v, f)
    np.testing.assert_array_equal(lo, v[f].min(axis=1))
    np.testing.assert_array_equal(hi, v[f].max(axis=1))


def test_a_grid_past_its_cap_grows_its_cells_and_still_holds_every_box(monkeypatch):
    from service.geometry import occupancy as module

    monkeypatch.setattr(module, "MAX_CELLS", 500)
    v, f = _bent_sphere()
    occupancy = Occupancy.build(v, f, 0.01)
    assert occupancy.full.size <= 500 and occupancy.cell > 0.01
    lo = v[f].min(axis=1) - 0.01
    assert occupancy.touching(lo, lo).all()


def test_dilation_is_a_cube_of_cells_around_each_set_one():
    from service.geometry.occupancy import dilate

    dims = np.array([5, 6, 7])
    full = np.zeros(dims.prod(), dtype=bool)
    full[np.ravel_multi_index((1, 2, 6), dims)] = True
    grown = dilate(full, dims, 2).reshape(dims)
    expected = np.zeros(dims, dtype=bool)
    expected[0:4, 0:5, 4:7] = True
    np.testing.assert_array_equal(grown, expected)
