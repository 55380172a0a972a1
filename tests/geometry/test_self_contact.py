"""Pressing a mesh whose parts cross into contact (``service.geometry.self_contact``)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from service.geometry.intersections import intersecting_pairs
from service.geometry.mesh import signed_volume
from service.geometry.self_contact import press_contacts, self_crossings


def _two_balls(overlap: float) -> tuple[np.ndarray, np.ndarray]:
    """Two radius-0.1 m icospheres as one mesh, their centres ``0.2 - overlap`` apart along x."""
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    v = np.concatenate([ball.vertices - [0.1 - overlap / 2, 0, 0], ball.vertices + [0.1 - overlap / 2, 0, 0]])
    f = np.concatenate([ball.faces, ball.faces + len(ball.vertices)])
    return v, f


@pytest.mark.parametrize("overlap", [0.0, 0.004, 0.03])
def test_self_crossings_is_intersecting_pairs(overlap):
    v, f = _two_balls(overlap)
    fast = self_crossings(v, f)
    reference = intersecting_pairs(v, f)
    assert sorted(map(tuple, fast)) == sorted(map(tuple, reference))
    assert (len(fast) > 0) == (overlap > 0)


def test_ignored_faces_drop_their_pairs():
    v, f = _two_balls(0.03)
    pairs = self_crossings(v, f)
    ignore = np.zeros(len(f), dtype=bool)
    ignore[pairs[:, 0]] = True
    assert len(self_crossings(v, f, ignore)) == 0


@pytest.mark.parametrize("overlap", [0.004, 0.02])
def test_two_balls_are_pressed_flat_against_each_other(overlap):
    """No crossing left, the two balls a hair apart at the contact (both gave way alike), the far sides
    untouched, and the volume lost of the order of the lens the overlap counted twice (the relaxation
    takes up to as much again around the flat: at most 3x)."""
    v, f = _two_balls(overlap)
    gap = 0.001
    out = press_contacts(v, f, gap)
    assert out.crossings == 0 and out.rounds >= 1
    assert len(self_crossings(out.vertices, f)) == 0
    n = len(v) // 2
    left, right = out.vertices[:n], out.vertices[n:]
    assert left[:, 0].max() < 0.0 + gap and right[:, 0].min() > 0.0 - gap  # each stays on its side
    assert abs(left[:, 0].max() + right[:, 0].min()) < 0.5 * overlap + gap  # symmetric
    far = np.abs(v[:, 0]) > 0.1  # the outer halves
    assert np.abs(out.vertices[far] - v[far]).max() == 0.0
    cap = overlap / 2
    lens = 2 * np.pi * cap**2 * (3 * 0.1 - cap) / 3  # the two caps' volume
    lost = signed_volume(v, f) - signed_volume(out.vertices, f)
    assert 0.5 * lens <= lost <= 3.0 * lens + np.pi * 0.1**2 * gap


def test_a_mesh_that_does_not_cross_comes_back_unchanged():
    v, f = _two_balls(0.0)
    v = v + [[0.0, 0.0, 0.0]]
    v[len(v) // 2 :, 0] += 0.01
    out = press_contacts(v, f, 0.001)
    assert out.rounds == 0 and out.moved == 0 and np.array_equal(out.vertices, v)


def test_only_tests_the_marked_faces():
    v, f = _two_balls(0.03)
    every = _set(self_crossings(v, f))
    assert _set(self_crossings(v, f, only=np.ones(len(f), dtype=bool))) == every
    left = np.arange(len(f)) < len(f) // 2
    assert _set(self_crossings(v, f, only=left)) == every  # each pair has a left face
    right_far = np.zeros(len(f), dtype=bool)
    right_far[np.flatnonzero(v[f].mean(axis=1)[:, 0] > 0.1)] = True
    assert len(self_crossings(v, f, only=right_far)) == 0


def _set(pairs: np.ndarray) -> set:
    return set(map(tuple, pairs.tolist()))
