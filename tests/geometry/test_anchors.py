"""``service.geometry.anchors``: garment vertices anchored to the body, and the faces that face it."""

from __future__ import annotations

import numpy as np
import trimesh

from service.geometry.anchors import BodyAnchors
from service.geometry.closest import ClosestPoint


def _sphere():
    s = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    return np.asarray(s.vertices), np.asarray(s.faces)


def test_anchors_are_the_closest_body_points_and_follow_the_body():
    body_v, body_f = _sphere()
    rng = np.random.default_rng(0)
    direction = rng.normal(size=(200, 3))
    rest = 0.13 * direction / np.linalg.norm(direction, axis=1, keepdims=True)  # 3 cm off the body
    anchors = BodyAnchors.build(rest, ClosestPoint.build(body_v, body_f))
    closest = ClosestPoint.build(body_v, body_f).query(rest).point
    np.testing.assert_allclose(anchors.on(body_v, body_f), closest, atol=1e-12)
    np.testing.assert_allclose(anchors.bary.sum(axis=1), 1.0)
    grown = body_v * [1.5, 1.0, 2.0]  # another body of the same topology: the anchors move with it
    on = anchors.on(grown, body_f)
    np.testing.assert_allclose(on, np.einsum("vk,vkx->vx", anchors.bary, grown[body_f[anchors.face]]))


def test_faces_turned_against_the_body_are_flagged_as_the_reference_flags_them():
    body_v, body_f = _sphere()
    shell = trimesh.creation.icosphere(subdivisions=2, radius=0.12)
    v, f = np.asarray(shell.vertices), np.asarray(shell.faces)
    anchors = BodyAnchors.build(v, ClosestPoint.build(body_v, body_f))
    assert not anchors.reversed_faces(v, f, body_v, body_f).any()  # wound outwards, as the body
    turned = f[:, ::-1]
    assert anchors.reversed_faces(v, turned, body_v, body_f).all()
    rng = np.random.default_rng(1)
    crumpled = v + rng.normal(scale=0.01, size=v.shape)
    ref = anchors.reversed_faces_reference(crumpled, f, body_v, body_f)
    assert 0.0 < ref.mean() < 0.5
    np.testing.assert_array_equal(anchors.reversed_faces(crumpled, f, body_v, body_f), ref)
