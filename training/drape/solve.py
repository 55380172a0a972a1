"""Quasi-static drape: minimise membrane + bending + gravity + body collision (+ waist pin,
+ static friction) with L-BFGS.

The garment starts carried onto the new body by the diffused body displacement (canonical
space). Its rest shape is graded ``grading`` (70 %) of the way to the body, as a shop's size
chart would; the remaining 30 % of the body's change makes it taut on a big body and loose on a
small one. Vertices that start near the skin stick to it tangentially (static friction):
without friction a loose top slides down its body as a whole, a mode only gravity drives.

Convergence criterion: every ``window`` (25) iterations the vertices are compared with their
positions a window earlier; the drape has converged when no vertex moved more than
``step_tol`` (0.2 mm) over the last window, or stops at ``max_iterations`` (600). The largest
motion over the last window is returned (``last_move``) so that a capped drape says how far
from rest it stopped. A force criterion does not work here: the stiff membrane against the weak
gravity leaves residual forces of tens of vertex weights that L-BFGS reduces only slowly while
the shape no longer changes. Loose cloth with buckling folds (the skirt's hem) has near-zero
stiffness modes that L-BFGS resolves slowly; those drapes hit the cap (see the benchmark).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.optimize

from service.geometry.mesh import face_normals
from service.pipeline.size_model import ONE_SIZE_GRADING
from training.drape import energy
from training.drape.energy import BodyPlanes, RestShape


@dataclass(frozen=True)
class Material:
    """Cloth parameters (a cotton-like knit, the values SNUG uses)."""

    mu: float = 11.1  # N/m, Lame shear modulus per unit area
    lam: float = 20.9  # N/m, Lame first parameter per unit area
    bending: float = 3.96e-5  # N m
    density: float = 0.15  # kg / m^2


@dataclass(frozen=True)
class DrapeSettings:
    material: Material = field(default_factory=Material)
    collision_stiffness: float = 2e5  # N / m^3 (per unit area): a 1 N/m^2 pressure sinks 5 um
    margin: float = 0.003  # m kept between cloth and skin
    pin_stiffness: float = 2e4  # N / m^3 (per unit area) for waistband vertices
    grading: float = ONE_SIZE_GRADING  # share of the body's change the rest shape follows (one size)
    friction_stiffness: float = 2e3  # N / m^3 (per unit area): a vertex's own weight shears it ~1 mm
    friction_band: float = 0.02  # m: cloth starting this close to the skin sticks, fading with distance
    step_tol: float = 2e-4  # m: converged when no vertex moved more than this over a window
    window: int = 25  # iterations
    max_iterations: int = 600


@dataclass
class DrapeProblem:
    """Everything the energy needs for one garment on one body."""

    rest: RestShape
    Q: object  # scipy sparse (V, V) bending matrix
    body: BodyPlanes
    pinned: np.ndarray  # (P,) int vertex ids held at pin_target
    pin_target: np.ndarray  # (P, 3)
    settings: DrapeSettings
    # (index (Q,), anchor (Q, 3), normal (Q, 3), weight (Q,)), see stick_to_skin
    friction: tuple | None = None

    def __post_init__(self):
        self.contacts = energy.ContactCache(self.body, self.settings.margin)

    @property
    def mass(self) -> np.ndarray:
        return self.settings.material.density * self.rest.vertex_area

    def energy(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """Total energy and gradient ``(V, 3)`` at ``x (V, 3)``."""
        s, m = self.settings, self.settings.material
        terms = [
            energy.membrane(x, self.rest, m.mu, m.lam),
            energy.bending(x, self.Q, m.bending),
            energy.gravity(x, self.mass),
            energy.collision(x, self.contacts, self.rest.vertex_area, s.collision_stiffness, s.margin),
        ]
        if len(self.pinned):
            w = self.rest.vertex_area[self.pinned]
            terms.append(energy.pin(x, self.pinned, self.pin_target, w, s.pin_stiffness))
        if self.friction is not None:
            terms.append(energy.friction(x, *self.friction, s.friction_stiffness))
        return sum(t[0] for t in terms), sum(t[1] for t in terms)

    def residual(self, x: np.ndarray) -> float:
        """Largest |force| / (m g) over the vertices."""
        _, g = self.energy(x)
        return float(np.max(np.linalg.norm(g, axis=1) / (self.mass * energy.GRAVITY)))


@dataclass
class DrapeResult:
    vertices: np.ndarray  # (V, 3) equilibrium positions
    iterations: int
    residual: float  # max |force| / (m g) at the end
    converged: bool
    energy: float
    message: str
    last_move: float  # m, largest vertex motion over the last full window: distance from rest


def body_planes(vertices: np.ndarray, faces: np.ndarray, spacing: float = 3e-3, seed: int = 0) -> BodyPlanes:
    """Dense samples of a closed body mesh ``(V, 3)``, ``(F, 3)`` with their face normals."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    fn = face_normals(vertices, faces, normalize=False)
    area = 0.5 * np.linalg.norm(fn, axis=1)
    # At least one sample per face so thin features (fingers, toes) are never missed.
    extra = rng.choice(len(faces), size=int(area.sum() / spacing**2), p=area / area.sum())
    tri = np.concatenate([np.arange(len(faces)), extra])
    r1, r2 = rng.random(len(tri)), rng.random(len(tri))
    s = np.sqrt(r1)
    w = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
    samples = np.einsum("nk,nkd->nd", w, vertices[faces[tri]])
    normals = (fn / np.maximum(2 * area[:, None], 1e-30))[tri]
    return BodyPlanes(samples, normals, cKDTree(samples), radius=1.7 * spacing)


def stick_to_skin(problem: DrapeProblem, start: np.ndarray) -> DrapeProblem:
    """Give ``problem`` static friction for the vertices of ``start (V, 3)`` near the skin.

    Without friction a garment larger than its body slides down it as a whole (a mode only
    gravity drives, which L-BFGS resolves in thousands of iterations) and ends far lower than
    cloth on skin does. Vertices within ``friction_band`` of the body stick tangentially where
    they were put on, with a weight fading from 1 at the skin to 0 at the band's edge.
    """
    d, grad = problem.body.signed_distance(start)
    closeness = np.clip(1 - d / problem.settings.friction_band, 0, 1)
    index = np.flatnonzero(closeness > 0)
    normal = grad[index] / np.maximum(np.linalg.norm(grad[index], axis=1, keepdims=True), 1e-12)
    weight = problem.rest.vertex_area[index] * closeness[index] ** 2
    problem.friction = (index, start[index].copy(), normal, weight)
    return problem


def drape(problem: DrapeProblem, start: np.ndarray) -> DrapeResult:
    """Minimise the problem's energy from ``start (V, 3)``."""
    s = problem.settings
    shape = start.shape
    state = {"iteration": 0, "anchor": start.copy(), "converged": False, "moved": np.inf}

    def fun(flat):
        e, g = problem.energy(flat.reshape(shape))
        return e, g.ravel()

    def callback(intermediate_result):
        state["iteration"] += 1
        if state["iteration"] % s.window:
            return
        x = intermediate_result.x.reshape(shape)
        moved = float(np.linalg.norm(x - state["anchor"], axis=1).max())
        state["anchor"], state["moved"] = x.copy(), moved
        if moved < s.step_tol:
            state["converged"] = True
            raise StopIteration

    res = scipy.optimize.minimize(
        fun, start.ravel(), jac=True, method="L-BFGS-B", callback=callback,
        options={"maxiter": s.max_iterations, "maxcor": 20, "ftol": 0.0, "gtol": 0.0},
    )  # fmt: skip
    x = res.x.reshape(shape)
    # A line search that cannot improve any more also means the shape stopped changing.
    converged = state["converged"] or (res.status == 2 and problem.residual(x) < 100)
    return DrapeResult(
        x, int(res.nit), problem.residual(x), converged, float(res.fun), str(res.message), state["moved"]
    )
