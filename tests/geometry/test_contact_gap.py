"""Contacts opened to a gap for cloth (``service.geometry.contact_gap``)."""

from __future__ import annotations

import numpy as np

from service.geometry.contact_gap import open_contacts
from service.geometry.self_contact import press_contacts, self_crossings
from tests.geometry.test_self_contact import _two_balls


def test_two_balls_in_contact_are_opened_to_the_gap():
    v, f = _two_balls(0.01)
    touching = press_contacts(v, f, 0.001).vertices
    gap = 0.01
    out = open_contacts(touching, f, gap)
    assert len(self_crossings(out, f)) == 0
    n = len(v) // 2
    between = out[n:, 0].min() - out[:n, 0].max()
    assert 0.8 * gap <= between <= 1.5 * gap  # each side gave way about half the gap
    far = np.abs(v[:, 0]) > 0.1  # the outer halves
    assert np.abs(out[far] - touching[far]).max() == 0.0


def test_parts_further_apart_than_the_gap_do_not_move():
    v, f = _two_balls(0.0)
    v = v.copy()
    v[len(v) // 2 :, 0] += 0.02
    assert np.array_equal(open_contacts(v, f, 0.01), v)
