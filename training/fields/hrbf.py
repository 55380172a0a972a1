"""Covariant field h of a garment (paper 3.1; docs/design.md section 3): HRBFs fitted at its openings.

Per opening, a Hermite RBF (Macedo et al. 2011) with Wendland's compactly supported C2 kernel around
a fixed linear part (the plane through the loop's centroid, facing out along its mean direction)
interpolates h = 0 at the boundary loop's vertices and grad h = the unit vector tangent
to the garment, orthogonal to the loop, pointing out through the opening::

    h_o(x) = sum_i alpha_i phi(|x - x_i|) + beta_i . grad phi(x - x_i) + a . x + b

An HRBF of a loop extends it to an unbounded surface; its positive side also holds regions far from
the opening (beyond the plane of an A-pose sleeve end lies the hip). So each opening's field is
intersected with the cylinder that extrudes its loop along its mean outward direction (radius
``CYLINDER_SCALE`` x the loop's radius + ``CYLINDER_MARGIN``), and the garment's field is the union
over its openings::

    h(x) = H tanh(max_o min(h_o(x), c_o(x)) / H),   c_o(x) = R_o - radial distance to axis_o

h > 0 in the volume extending the openings, h < 0 over the garment. The tanh saturation at
``SATURATION`` (10 cm) keeps the field distance-like near the openings, where it matters, and bounded
further away. All functions are pure numpy; gradients are exact where the max/min are not tied.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.geometry.mesh import vertex_normals

MAX_CENTRES = 64
"""Loop vertices kept per opening (evenly along the loop): the HRBF system is 4 n + 4 unknowns."""
SUPPORT_SCALE = 1.0
"""Kernel support as a multiple of the loop's radius: beyond it only the plane remains (a cubic
kernel's growth, or a fitted linear part, flips signs far from a non-planar loop)."""
CYLINDER_SCALE = 1.0
CYLINDER_MARGIN = 0.02  # m
SATURATION = 0.1  # m


def wendland(r: np.ndarray, support: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Wendland's C2 kernel phi(r) = (1 - r/s)^4 (4 r/s + 1) for r < s, as (phi, psi, chi) with
    psi = phi'(r) / r and chi = psi'(r) / r, so that grad phi(v) = psi v and
    hess phi(v) = psi I + chi v v^T (chi v v^T -> 0 at r = 0)."""
    t = np.clip(1 - r / support, 0.0, None)
    phi = t**4 * (4 * (1 - t) + 1)
    psi = -20 / support**2 * t**3
    chi = 60 / support**3 * t**2 / np.where(r > 0, r, 1.0)
    return phi, psi, chi


@dataclass
class HRBF:
    """One opening's Hermite RBF: centres (n, 3), alpha (n,), beta (n, 3), linear part a (3,), b,
    kernel support (m)."""

    centres: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    a: np.ndarray
    b: float
    support: float

    def __call__(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(h ``(P,)``, grad h ``(P, 3)``) at ``x (P, 3)``."""
        v = x[:, None, :] - self.centres[None]  # (P, n, 3)
        phi, psi, chi = wendland(np.linalg.norm(v, axis=2), self.support)  # (P, n)
        vb = np.einsum("pnd,nd->pn", v, self.beta)
        value = phi @ self.alpha + (psi * vb).sum(1) + x @ self.a + self.b
        grad = np.einsum("pn,pnd->pd", psi * self.alpha + chi * vb, v) + psi @ self.beta
        return value, grad + self.a


def fit_hrbf(points: np.ndarray, normals: np.ndarray, support: float, a: np.ndarray, b: float) -> HRBF:
    """HRBF with h(points) = 0 and grad h(points) = normals, ``points, normals (n, 3)``, around the
    fixed linear part ``a . x + b`` (the kernel is positive definite: no side conditions needed)."""
    points, normals = np.asarray(points, np.float64), np.asarray(normals, np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or normals.shape != points.shape:
        raise ValueError(f"points and normals must be (n, 3), got {points.shape} and {normals.shape}")
    n = len(points)
    v = points[:, None] - points[None]  # (n_j, n_i, 3): x_j - x_i
    phi, psi, chi = wendland(np.linalg.norm(v, axis=2), support)
    hess = psi[..., None, None] * np.eye(3) + chi[..., None, None] * v[..., :, None] * v[..., None, :]
    m = np.zeros((4 * n, 4 * n))
    # rows 0..n-1: values; n..4n-1: gradients (3 per point)
    m[:n, :n] = phi
    m[:n, n:] = (psi[..., None] * v).reshape(n, 3 * n)
    m[n:, :n] = (psi[..., None] * v).transpose(0, 2, 1).reshape(3 * n, n)
    m[n:, n:] = hess.transpose(0, 2, 1, 3).reshape(3 * n, 3 * n)
    rhs = np.concatenate([-(points @ a + b), (normals - a).reshape(-1)])
    sol = np.linalg.lstsq(m, rhs, rcond=None)[0]
    return HRBF(points, sol[:n], sol[n:].reshape(n, 3), np.asarray(a, np.float64), float(b), support)


def opening_directions(vertices: np.ndarray, faces: np.ndarray, loop: np.ndarray) -> np.ndarray:
    """Unit vectors ``(L, 3)`` at the loop vertices: tangent to the garment, orthogonal to the loop,
    pointing out through the opening (away from the rest of the garment)."""
    p = vertices[loop]
    tangent = np.roll(p, -1, axis=0) - np.roll(p, 1, axis=0)
    normal = vertex_normals(vertices, faces)[loop]
    d = np.cross(tangent, normal)
    d -= np.einsum("ld,ld->l", d, normal)[:, None] * normal
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    # Orient by the garment's own side: from each loop vertex's neighbours off the loop to it.
    on_loop = np.zeros(len(vertices), dtype=bool)
    on_loop[loop] = True
    slot = np.full(len(vertices), -1)
    slot[loop] = np.arange(len(loop))
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.concatenate([e, e[:, ::-1]])
    e = e[on_loop[e[:, 0]] & ~on_loop[e[:, 1]]]  # (loop vertex, inner neighbour)
    outward = np.zeros_like(p)
    np.add.at(outward, slot[e[:, 0]], vertices[e[:, 0]] - vertices[e[:, 1]])
    # One orientation for the whole loop (the loop's order fixes it), decided by the majority.
    sign = 1.0 if np.einsum("ld,ld->l", d, outward).sum() >= 0 else -1.0
    return sign * d


@dataclass
class Opening:
    """An opening's HRBF and the cylinder extruding its loop: axis origin (3,), unit axis (3,), radius."""

    hrbf: HRBF
    origin: np.ndarray
    axis: np.ndarray
    radius: float

    def field(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(min(h_o, c_o) ``(P,)``, its gradient ``(P, 3)``) at ``x (P, 3)``."""
        h, gh = self.hrbf(x)
        rel = x - self.origin
        radial = rel - (rel @ self.axis)[:, None] * self.axis
        rho = np.linalg.norm(radial, axis=1)
        c = self.radius - rho
        gc = -radial / np.maximum(rho, 1e-12)[:, None]
        use_h = h <= c
        return np.where(use_h, h, c), np.where(use_h[:, None], gh, gc)


def build_openings(vertices: np.ndarray, faces: np.ndarray, loops: dict[str, np.ndarray]) -> list[Opening]:
    """Every opening of a garment mesh ``vertices (V, 3)``, ``faces (F, 3)``; loops: name -> (L,) ids."""
    vertices = np.asarray(vertices, dtype=np.float64)
    openings = []
    for name in sorted(loops):
        loop = np.asarray(loops[name])
        directions = opening_directions(vertices, faces, loop)
        keep = np.linspace(0, len(loop), min(MAX_CENTRES, len(loop)), endpoint=False).astype(int)
        origin = vertices[loop].mean(axis=0)
        axis = directions.mean(axis=0)
        axis /= np.linalg.norm(axis)
        rel = vertices[loop] - origin
        loop_radius = float(np.linalg.norm(rel - (rel @ axis)[:, None] * axis, axis=1).max())
        support = SUPPORT_SCALE * loop_radius
        hrbf = fit_hrbf(vertices[loop[keep]], directions[keep], support, axis, -float(axis @ origin))
        radius = CYLINDER_SCALE * loop_radius + CYLINDER_MARGIN
        openings.append(Opening(hrbf, origin, axis, radius))
    return openings


def covariant_field(openings: list[Opening], x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(h ``(P,)``, grad h ``(P, 3)``) of a garment with these openings at ``x (P, 3)``."""
    x = np.asarray(x, dtype=np.float64)
    if not openings:
        return np.full(len(x), -SATURATION), np.zeros_like(x)
    values, grads = zip(*(o.field(x) for o in openings), strict=True)
    values, grads = np.stack(values), np.stack(grads)  # (O, P), (O, P, 3)
    best = np.argmax(values, axis=0)
    rows = np.arange(len(x))
    h, g = values[best, rows], grads[best, rows]
    t = np.tanh(h / SATURATION)
    return SATURATION * t, (1 - t**2)[:, None] * g
