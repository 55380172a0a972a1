"""Cloth energies against finite differences, and a square of cloth draped over a sphere."""

import numpy as np
import pytest
import trimesh

from service.geometry.mesh import face_normals
from tests.meshes import grid_mesh
from training.drape import energy
from training.drape.solve import DrapeProblem, DrapeSettings, body_planes, drape

H = 1e-6  # central-difference step, m
RTOL = 1e-5  # on directional derivatives of smooth energies in float64


def _bent_sheet(n=6, seed=0):
    """A 0.3 m sheet (rest: flat) stretched, sheared and bent into a non-trivial state."""
    v, f = grid_mesh(n)
    rest = v * 0.3
    rng = np.random.default_rng(seed)
    x = rest @ np.array([[1.1, 0.1, 0.0], [0.0, 0.9, 0.1], [0.0, 0.0, 1.0]])
    x[:, 2] += 0.05 * np.sin(4 * x[:, 0]) + 0.01 * rng.normal(size=len(x))
    return rest, f, x


def _directional_check(fun, x, seed=1):
    e, g = fun(x)
    d = np.random.default_rng(seed).normal(size=x.shape)
    fd = (fun(x + H * d)[0] - fun(x - H * d)[0]) / (2 * H)
    analytic = float(np.sum(g * d))
    assert fd == pytest.approx(analytic, rel=RTOL, abs=1e-10)


def test_membrane_gradient_matches_finite_differences():
    rest, f, x = _bent_sheet()
    r = energy.rest_shape(rest, f)
    _directional_check(lambda y: energy.membrane(y, r, 11.1, 20.9), x)


def test_membrane_is_zero_at_rest_and_under_rigid_motion():
    rest, f, _ = _bent_sheet()
    r = energy.rest_shape(rest, f)
    q, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))
    for y in (rest, rest @ q.T + np.array([0.3, -1.0, 2.0])):
        e, g = energy.membrane(y, r, 11.1, 20.9)
        assert e == pytest.approx(0.0, abs=1e-14)
        assert np.abs(g).max() < 1e-12


def test_membrane_matches_uniaxial_stretch_by_hand():
    # Stretch by s along x only: G = diag((s^2-1)/2, 0), psi = (mu + lam/2) G_xx^2 per area.
    rest, f, _ = _bent_sheet()
    r = energy.rest_shape(rest, f)
    s, mu, lam = 1.2, 11.1, 20.9
    e, _ = energy.membrane(rest * np.array([s, 1, 1]), r, mu, lam)
    gxx = (s**2 - 1) / 2
    assert e == pytest.approx((mu + lam / 2) * gxx**2 * 0.3**2, rel=1e-10)


def test_bending_gradient_and_flat_invariance():
    rest, f, x = _bent_sheet()
    Q = energy.bending_matrix(rest, f)
    _directional_check(lambda y: energy.bending(y, Q, 3.96e-5), x)
    # Flat rest state: any rigid motion of the flat sheet, and any in-plane stretch, costs nothing.
    q, _ = np.linalg.qr(np.random.default_rng(4).normal(size=(3, 3)))
    for y in (rest @ q.T, rest * np.array([1.3, 0.8, 1.0])):
        assert abs(energy.bending(y, Q, 1.0)[0]) < 1e-10 * energy.bending(x, Q, 1.0)[0]
    assert energy.bending(x, Q, 1.0)[0] > 1e-3


def test_bending_equals_the_dihedral_angle_form_for_isometric_bends():
    # Bergou et al. 2006: for an isometric deformation of a flat sheet the quadratic energy equals
    # the hinge energy 1/2 sum_e 3 |e|^2 / (A0 + A1) * (2 sin(theta_e / 2))^2, computed here
    # independently from the dihedral angles of a sheet rolled onto a cylinder (to O(theta^2):
    # 3e-4 apart at this resolution, 1.3e-3 at half of it).
    v, f = grid_mesh(24)
    rest = v * np.array([0.3, 0.3, 0.0])
    R = 0.2
    theta = rest[:, 0] / R
    rolled = np.stack([R * np.sin(theta), rest[:, 1], R * (1 - np.cos(theta))], axis=1)
    e, _ = energy.bending(rolled, energy.bending_matrix(rest, f), 1.0)
    pairs = {}
    for t, tri in enumerate(f):
        for k in range(3):
            pairs.setdefault(tuple(sorted((tri[k], tri[(k + 1) % 3]))), []).append(t)
    normals = face_normals(rolled, f)
    areas = 0.5 * np.linalg.norm(face_normals(rest, f, normalize=False), axis=1)
    hinge = 0.0
    for (i, j), faces in pairs.items():
        if len(faces) == 2:
            a, b = faces
            angle = np.arccos(np.clip(normals[a] @ normals[b], -1, 1))
            hinge += (
                3 * np.sum((rest[i] - rest[j]) ** 2) / (areas[a] + areas[b]) * (2 * np.sin(angle / 2)) ** 2
            )
    assert e == pytest.approx(0.5 * hinge, rel=1e-3)


def test_gravity_and_pin_gradients():
    rest, f, x = _bent_sheet()
    mass = np.linspace(0.01, 0.02, len(x))
    _directional_check(lambda y: energy.gravity(y, mass), x)
    idx = np.array([0, 3, 7])
    target = x[idx] + 0.01
    w = np.array([1.0, 2.0, 3.0])
    _directional_check(lambda y: energy.pin(y, idx, target, w, 50.0), x)


def test_friction_gradient_and_free_normal_motion():
    rest, f, x = _bent_sheet()
    idx = np.array([1, 4, 9, 16])
    anchor = x[idx] - 0.01
    normal = np.random.default_rng(2).normal(size=(4, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    w = np.array([1.0, 0.5, 2.0, 1.5])
    _directional_check(lambda y: energy.friction(y, idx, anchor, normal, w, 30.0), x)
    # Moving only along the body normal costs nothing: friction resists sliding, not lifting.
    y = x.copy()
    y[idx] = anchor + 0.02 * normal
    e, g = energy.friction(y, idx, anchor, normal, w, 30.0)
    assert e == pytest.approx(0.0, abs=1e-15) and np.abs(g).max() < 1e-12


@pytest.fixture(scope="module")
def sphere():
    s = trimesh.creation.icosphere(subdivisions=4, radius=0.1)
    return np.asarray(s.vertices), np.asarray(s.faces)


def test_smooth_body_distance_gradient_and_accuracy(sphere):
    v, f = sphere
    planes = body_planes(v, f, spacing=3e-3)
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(200, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    radii = rng.uniform(0.095, 0.11, 200)
    x = dirs * radii[:, None]
    d, g = planes.signed_distance(x)
    # The faceted icosphere sits up to 0.12 mm inside the true sphere between its vertices.
    assert np.abs(d - (radii - 0.1)).max() < 3e-4
    for e in np.eye(3):
        fd = (planes.signed_distance(x + H * e)[0] - planes.signed_distance(x - H * e)[0]) / (2 * H)
        np.testing.assert_allclose(fd, g @ e, atol=1e-5)


def test_collision_gradient_and_contact_cache(sphere):
    v, f = sphere
    planes = body_planes(v, f, spacing=3e-3)
    rng = np.random.default_rng(1)
    dirs = rng.normal(size=(300, 3))
    x = dirs / np.linalg.norm(dirs, axis=1, keepdims=True) * rng.uniform(0.097, 0.12, 300)[:, None]
    w = rng.uniform(1e-4, 2e-4, 300)
    _directional_check(lambda y: energy.collision(y, planes, w, 2e5, 0.003), x)
    # The cache answers exactly like the uncached query, however the points move.
    cache = energy.ContactCache(planes, 0.003)
    for step in range(5):
        y = x + 0.004 * step * rng.normal(size=x.shape)
        e0, g0 = energy.collision(y, planes, w, 2e5, 0.003)
        e1, g1 = energy.collision(y, cache, w, 2e5, 0.003)
        assert e1 == pytest.approx(e0, rel=1e-12, abs=1e-18)
        np.testing.assert_allclose(g1, g0, atol=1e-15)


def test_cloth_square_drapes_over_a_sphere(sphere):
    """A 0.4 m square laid 1 cm above a 0.1 m sphere hangs around it, at rest, outside it.

    The cloth is frictionless, so its centre vertex is pinned above the pole (else it slides off).
    """
    sv, sf = sphere
    v, f = grid_mesh(20)
    rest = (v - [0.5, 0.5, 0.0]) * 0.4
    start = rest + [0.0, 0.0, 0.11]
    settings = DrapeSettings(max_iterations=3000)
    centre = np.argmin(np.linalg.norm(rest, axis=1))
    problem = DrapeProblem(
        energy.rest_shape(rest, f), energy.bending_matrix(rest, f), body_planes(sv, sf, spacing=3e-3),
        np.array([centre]), np.array([[0.0, 0.0, 0.1 + settings.margin]]), settings,
    )  # fmt: skip
    result = drape(problem, start)
    x = result.vertices
    assert result.converged, result.message
    r = np.linalg.norm(x, axis=1)
    assert r.min() > 0.1 - 1e-3, "no vertex more than 1 mm inside the sphere"
    # The centre rests on the top, within the collision margin; the corners hang well below it.
    assert x[centre, 2] == pytest.approx(0.1 + settings.margin, abs=1.5e-3)
    corners = np.argsort(-np.linalg.norm(rest, axis=1))[:4]
    assert np.all(x[corners, 2] < 0.02)
    # Nearly inextensible: edges change length by at most a few percent.
    e = np.sort(f[:, [0, 1]], axis=1)
    ratio = np.linalg.norm(x[e[:, 0]] - x[e[:, 1]], axis=1) / np.linalg.norm(
        rest[e[:, 0]] - rest[e[:, 1]], axis=1
    )
    assert np.abs(ratio - 1).max() < 0.08
