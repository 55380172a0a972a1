"""Closest points against the brute-force reference; the diffused body displacement B~s."""

import numpy as np
import pytest

from service.geometry.closest import ClosestPoint, closest_point_reference
from service.geometry.mesh import unique_edges, vertex_normals
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.canonical import CHUNK, NEAR_TRIANGLES, CanonicalSpace


@pytest.fixture(scope="module")
def body():
    model = BodyModel.load()
    return model, model.vertices(np.asarray(DEFAULT_BETA)), model.faces


@pytest.fixture(scope="module")
def space(body):
    _, mean, faces = body
    return CanonicalSpace.build(mean, faces)


def test_closest_points_match_the_brute_force_reference(body):
    _, v, f = body
    rng = np.random.default_rng(0)
    points = v[rng.integers(0, len(v), 300)] + rng.normal(0, 0.02, (300, 3))
    fast = ClosestPoint.build(v, f).query(points)
    ref = closest_point_reference(points, v, f)
    np.testing.assert_allclose(fast.distance, ref.distance, atol=1e-12)
    np.testing.assert_allclose(fast.point, ref.point, atol=1e-12)
    # Points pushed out along their face normal come back to where they started, signed +.
    face = rng.integers(0, len(f), 200)
    on = v[f[face]].mean(axis=1)
    n = np.cross(v[f[face, 1]] - v[f[face, 0]], v[f[face, 2]] - v[f[face, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    c = ClosestPoint.build(v, f).query(on + 1e-4 * n)
    assert np.all(c.signed > 0)


def test_diffused_displacement_equals_body_displacement_on_the_surface(body, space):
    model, mean, f = body
    other = model.vertices(np.array([0.1, 0.65, 0.9]))
    rng = np.random.default_rng(1)
    face = rng.integers(0, len(f), 2000)
    bary = rng.dirichlet([1, 1, 1], 2000)
    on_mean = np.einsum("nk,nkd->nd", bary, mean[f[face]])
    on_other = np.einsum("nk,nkd->nd", bary, other[f[face]])
    np.testing.assert_allclose(space.to_body(on_mean, other), on_other, atol=1e-9)
    # The mean body itself has no displacement anywhere.
    off = on_mean + rng.normal(0, 0.03, on_mean.shape)
    np.testing.assert_allclose(space.displacement(off, mean), 0.0, atol=1e-12)


def test_diffused_displacement_does_not_tear_a_shell(body, space):
    """A shell 1 cm outside a heavy body's clothed regions neither tears nor collapses.

    Where closest points jump across the medial axis (armpits, crotch) a plain closest-point
    transfer tears the shell (edge ratios of 10 and more). Measured with the blend: edge length
    ratios 0.69 to 2.86 (the armpit of the upper arm, which a heavy body squeezes shut; the body
    itself stretches its edges 0.60 to 2.09).
    """
    model, mean, f = body
    other = model.vertices(np.array([0.0, 0.6, 0.8]))
    shell = mean + 0.01 * vertex_normals(mean, f)
    moved = space.to_body(shell, other)
    names = np.asarray(model.region_names)[model.regions]
    clothed = ~np.isin(names, ["head", "hand_l", "hand_r", "foot_l", "foot_r"])
    e = unique_edges(f)
    e = e[clothed[e[:, 0]] & clothed[e[:, 1]]]
    ratio = np.linalg.norm(moved[e[:, 0]] - moved[e[:, 1]], axis=1) / np.linalg.norm(
        shell[e[:, 0]] - shell[e[:, 1]], axis=1
    )
    assert 0.5 < ratio.min() and ratio.max() < 3.0


def test_to_canonical_inverts_to_body(body, space):
    model, mean, f = body
    other = model.vertices(np.array([1.0, 0.3, 0.2]))
    rng = np.random.default_rng(2)
    x = mean[rng.integers(0, len(mean), 500)] + rng.normal(0, 0.015, (500, 3))
    y = space.to_body(x, other)
    back, residual = space.to_canonical(y, other)
    assert residual < 1e-3
    assert np.median(np.linalg.norm(back - x, axis=1)) < 1e-5


@pytest.mark.parametrize("threads", [1, 2])
def test_fast_transfer_matches_the_reference(body, space, threads):
    """The fast transfer (one shared neighbour query, distinct pairs tested once, partition, blocks on
    threads, no near term beyond BLEND_DISTANCE) gives the reference's displacement to rounding: on
    the surface, near it, inside, up to 15 cm out (where only the far term is left) and for more
    points than one block."""
    model, mean, f = body
    fast = CanonicalSpace(space.mean_vertices, space.faces, space.closest, threads)
    rng = np.random.default_rng(4)
    n = CHUNK + 1500
    face = rng.integers(0, len(f), n)
    on = np.einsum("nk,nkd->nd", rng.dirichlet([1, 1, 1], n), mean[f[face]])
    normal = vertex_normals(mean, f)[f[face, 0]]
    points = on + normal * rng.uniform(-0.01, 0.15, (n, 1))
    points[:200] = on[:200]
    for beta in ([0.0, 0.12, 1.0], [1.0, 0.72, 0.0]):
        d = model.vertices(np.array(beta)) - mean
        ref = space.transfer_weights_reference(points).apply(d)
        got = fast.transfer_weights(points).apply(d)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10)
    # Where the near term is skipped, the reference's is exactly 0 too.
    near = 3 * NEAR_TRIANGLES
    skipped = ~fast.transfer_weights(points).weight[:, :near].any(axis=1)
    assert 0 < skipped.sum() < n
    assert not space.transfer_weights_reference(points[skipped]).weight[:, :near].any()
    assert fast.transfer_weights(points[:0]).weight.shape[0] == 0


def test_to_bodies_carries_each_set_as_to_body_alone(body, space):
    """A request's garments in one pass (``to_bodies``, its blocks cut across the sets) land where
    each lands alone, bit for bit (``tests/pipeline/test_outfit.py`` compares the pipeline's world meshes with
    ``to_body`` exactly), and where the reference puts them."""
    model, mean, _ = body
    other = model.vertices(np.array([0.3, 0.8, 0.4]))
    rng = np.random.default_rng(5)
    sizes = (700, 0, CHUNK + 900, 1)
    sets = [mean[rng.integers(0, len(mean), n)] + rng.normal(0, 0.03, (n, 3)) for n in sizes]
    together = space.to_bodies(sets, other)
    assert [len(y) for y in together] == [len(x) for x in sets]
    for x, y in zip(sets, together, strict=True):
        assert np.array_equal(y, space.to_body(x, other))
    x = np.concatenate(sets)
    ref = x + space.transfer_weights_reference(x).apply(other - mean)
    np.testing.assert_allclose(np.concatenate(together), ref, rtol=0, atol=1e-10)
    assert space.to_bodies([], other) == []
