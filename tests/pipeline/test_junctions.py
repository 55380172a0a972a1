"""``collisions.junctions``: where the outer garment comes down, by how much, and where not, on
the cylinder bodies of ``test_layering`` (the catalog's pairs: ``test_outfit``)."""

from __future__ import annotations

import numpy as np
import pytest

from service.pipeline.collisions import junctions
from service.pipeline.collisions.layering import junction_run
from service.pipeline.collisions.settings import SETTINGS
from tests.pipeline import test_layering
from tests.pipeline.test_layering import closed, profile, tube

legs_body = test_layering.legs_body  # the fixture: torso over two legs


def test_saddles_lie_between_the_torso_and_each_arm_or_between_the_legs():
    centres = np.array([[0.0, 0.0], [0.3, 0.1], [-0.3, 0.1]])
    arms = junctions.saddles(frozenset({0, 1, 2}), centres, ["torso", "arm", "arm"])
    np.testing.assert_allclose(arms, [[0.15, 0.05], [-0.15, 0.05]])
    legs = junctions.saddles(frozenset({0, 1}), centres[1:], ["leg", "leg"])
    np.testing.assert_allclose(legs, [[0.0, 0.1]])


def test_the_outer_crotch_comes_down_below_the_inner_one_and_nothing_else_moves(legs_body):
    parts = (tube(0.18, 0.8, 1.05), tube(0.08, 0.1, 0.8, -0.09), tube(0.08, 0.1, 0.8, 0.09))
    pants_v, _ = closed(*parts)
    pants = profile("pants", legs_body, *parts)
    mini = profile("mini", legs_body, tube(0.22, 0.77, 1.05))  # its hem 3 cm below the crotch
    run = junction_run(mini, pants, legs_body)
    drop = junctions.lowering(mini, pants, legs_body, pants_v)
    assert drop.shape == pants_v.shape and np.all(drop[:, :2] == 0) and np.all(drop[:, 2] <= 0)
    depth = run[0] * SETTINGS.slice_step + SETTINGS.extra
    assert drop[:, 2].max() == 0 and -drop[:, 2].min() == pytest.approx(depth)
    saddle = pants_v[np.argmin(drop[:, 2])]
    r = np.linalg.norm(pants_v - saddle, axis=1)
    radius = max(SETTINGS.bump_radius * depth, SETTINGS.min_bump_radius)
    moved = drop[:, 2] < 0
    assert np.all(r[moved] < radius)  # the bump's reach
    assert np.all(pants_v[moved, 2] < saddle[2] + SETTINGS.gate)  # the waistband above stays
    assert abs(saddle[0]) < 0.02  # between the legs
    # the other order, and an inner garment whose junction is no lower: nothing to let down
    assert junctions.lowering(pants, mini, legs_body, closed(tube(0.22, 0.77, 1.05))[0]) is None
    assert junctions.lowering(pants, pants, legs_body, pants_v) is None


def test_each_garment_let_down_around_the_same_one_takes_its_own_room(legs_body):
    # Two bottoms over a mini: the outer one's crotch comes down EXTRA below the inner one's, which
    # itself comes down EXTRA below the mini's hem: one EXTRA more, over a bump that much wider.
    parts = (tube(0.18, 0.8, 1.05), tube(0.08, 0.1, 0.8, -0.09), tube(0.08, 0.1, 0.8, 0.09))
    pants_v, _ = closed(*parts)
    pants = profile("pants", legs_body, *parts)
    mini = profile("mini", legs_body, tube(0.22, 0.77, 1.05))
    alone, below = (junctions.lowering(mini, pants, legs_body, pants_v, between) for between in (0, 1))
    assert -below[:, 2].min() == pytest.approx(-alone[:, 2].min() + SETTINGS.extra)
    assert np.all(below[:, 2] <= alone[:, 2])
    assert (below[:, 2] < alone[:, 2]).sum() > (alone[:, 2] < 0).sum() // 2  # the bump grows with the drop


def test_the_drop_is_read_on_the_body_the_garments_are_worn_on(legs_body):
    # The drapes on the mean body put the mini's hem 3 cm below the pants' crotch; on another body its
    # explicit mesh hangs 8 cm below (and the pants are unchanged): the run on that body is 8 levels,
    # the drop 8 cm + EXTRA, the bump where the drapes put it. A hem above the crotch there: no run, a
    # drop of EXTRA alone.
    parts = (tube(0.18, 0.8, 1.05), tube(0.08, 0.1, 0.8, -0.09), tube(0.08, 0.1, 0.8, 0.09))
    pants_v, pants_f = closed(*parts)
    pants = profile("pants", legs_body, *parts)
    mini = profile("mini", legs_body, tube(0.22, 0.77, 1.05))
    assert junction_run(mini, pants, legs_body)[0] == 3
    for hem, length in ((0.72, 8), (0.83, 0)):
        here_v, here_f = closed(tube(0.22, hem, 1.05))
        assert junctions.body_run(mini, pants, legs_body, here_v, here_f, pants_v, pants_f) == length
        if length:  # the whole-profile run agrees with the one sliced near the drapes' run
            whole = profile("mini", legs_body, tube(0.22, hem, 1.05))
            assert junction_run(whole, pants, legs_body)[0] == length
        drop = junctions.lowering(mini, pants, legs_body, pants_v, length=length)
        assert -drop[:, 2].min() == pytest.approx(length * SETTINGS.slice_step + SETTINGS.extra)
        drapes = junctions.lowering(mini, pants, legs_body, pants_v)
        assert np.argmin(drop[:, 2]) == np.argmin(drapes[:, 2])  # the same saddle


def test_drops_for_several_inner_garments_take_the_deepest():
    a, b = np.zeros((3, 3)), np.zeros((3, 3))
    a[:, 2], b[:, 2] = [-0.1, 0.0, -0.02], [-0.05, -0.03, 0.0]
    np.testing.assert_array_equal(junctions.combined([a, b])[:, 2], [-0.1, -0.03, -0.02])
    assert junctions.combined([]) is None


def test_a_top_tucked_into_pants_is_gathered_up_above_their_crotch(legs_body):
    # A long top (hem 10 cm below the crotch, wrapping both legs) tucked into pants: its hem rises above
    # the pants' crotch, heights keep their order (gathered, not folded), and what is above the gate or
    # beside the hem (a sleeve's cuff) stays.
    pants_parts = (tube(0.18, 0.8, 1.05), tube(0.08, 0.1, 0.8, -0.09), tube(0.08, 0.1, 0.8, 0.09))
    pants_v, _ = closed(*pants_parts)
    pants = profile("pants", legs_body, *pants_parts)
    top_parts = (tube(0.2, 0.7, 1.4, sections=64), tube(0.03, 0.6, 0.9, 0.5))  # body, a hanging cuff
    top_v, top_f = closed(*top_parts)
    top = profile("top", legs_body, *top_parts)
    gathering = junctions.raising(top, pants, legs_body, top_v, top_f, pants_v)
    crotch = pants_v[gathering.crotch, 2].max()
    assert abs(crotch - 0.8) < 1e-9  # the legs' tops, where the pants' tubes meet
    shift = gathering.shift(top_v, pants_v)
    assert np.all(shift[:, :2] == 0) and np.all(shift[:, 2] >= 0)
    z = top_v[:, 2] + shift[:, 2]
    hem = np.linalg.norm(top_v[:, :2], axis=1) < 0.21
    assert z[hem].min() == pytest.approx(crotch + SETTINGS.extra)
    order = np.argsort(top_v[hem, 2], kind="stable")
    assert np.all(np.diff(z[hem][order]) >= -1e-12)
    top_of_gather = crotch + SETTINGS.extra + max(SETTINGS.gate, crotch + SETTINGS.extra - 0.7)
    assert np.all(shift[top_v[:, 2] >= top_of_gather, 2] == 0)
    assert np.all(shift[~hem, 2] == 0)  # the cuff beside the hips
    # a top whose hem is above the crotch, and the pants' crotch for a top that hangs no lower: nothing
    short_parts = (tube(0.2, 0.85, 1.4),)
    short = profile("short", legs_body, *short_parts)
    assert junctions.raising(short, pants, legs_body, *closed(*short_parts), pants_v) is None
    assert gathering.shift(top_v + [0, 0, 0.2], pants_v) is None


def test_drops_and_rises_combine_per_vertex():
    down, up = np.zeros((3, 3)), np.zeros((3, 3))
    down[:, 2], up[:, 2] = [-0.1, 0.0, -0.02], [0.0, 0.05, 0.03]
    np.testing.assert_allclose(junctions.combined([down, up])[:, 2], [-0.1, 0.05, 0.01])


def test_a_room_in_place_of_extra_comes_down_that_much_further(legs_body):
    # SETTINGS.rooms: an outfit left crossing is made again with more room below the junction; the
    # drop is the run plus the room, once per garment let down around the same inner one.
    parts = (tube(0.18, 0.8, 1.05), tube(0.08, 0.1, 0.8, -0.09), tube(0.08, 0.1, 0.8, 0.09))
    pants_v, _ = closed(*parts)
    pants = profile("pants", legs_body, *parts)
    mini = profile("mini", legs_body, tube(0.22, 0.77, 1.05))
    run = junction_run(mini, pants, legs_body)[0]
    assert SETTINGS.rooms[0] == SETTINGS.extra and list(SETTINGS.rooms) == sorted(set(SETTINGS.rooms))
    for room in SETTINGS.rooms:
        for between in (0, 1):
            drop = junctions.lowering(mini, pants, legs_body, pants_v, between, extra=room)
            assert -drop[:, 2].min() == pytest.approx(run * SETTINGS.slice_step + room * (1 + between))
