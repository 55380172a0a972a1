"""Runtime Anny body (numpy only): shape code -> rest mesh, and human units -> shape code.

beta is ``(gender, height, weight)`` in Anny phenotype units, each in [0, 1] (gender 0 male,
1 female); the other phenotypes are fixed at export (npz metadata). With them fixed, Anny's rest
vertices are exactly multilinear in the 1-D hat interpolation coefficients ``a`` of the three
phenotypes over their anchors (gender 2, height 2, weight 3)::

    vertices(beta) = sum_{i,j,k} a_gender[i] a_height[j] a_weight[k] V_ijk      (12 corners)

so ``models/body/anny_shape.npz`` (built and checked against Anny by ``python -m export.body``)
stores the 12 corner bodies V_ijk. Frame: Anny rest pose (A-pose), metres, Z up, body facing -Y,
the body's left at +X.

Human units. Height is the z extent of the rest mesh, mass its enclosed volume times
``BODY_DENSITY_KG_M3``. Both are cheap and exact in the corner weights ``w (12,)``: z is linear in
``w`` and the volume is the cubic form ``sum_abc T_abc w_a w_b w_c`` with a ``(12, 12, 12)`` tensor
``T`` computed once from the corners (``volume_tensor``), so ``shape_from_measurements`` runs
Newton's method with exact Jacobians in a few milliseconds.

Supported adult range: any gender in [0, 1] and the parameter box ``SUPPORTED_HEIGHT_PARAM x
SUPPORTED_WEIGHT_PARAM``. Measured at its corners (``python -m benchmarks.body_parity``)::

    gender  height  weight   height cm   mass kg   BMI
    0       0.12    0        149.5        38.4     17.2
    0       0.12    1        149.5        74.4     33.3
    0       0.72    0        214.8        89.7     19.4
    0       0.72    1        214.8       154.0     33.4
    1       0.12    0        135.6        25.7     14.0
    1       0.12    1        135.5        51.7     28.2
    1       0.72    0        201.0        66.3     16.4
    1       0.72    1        200.8       116.1     28.8

Anny's height axis is linear (108.9 cm per unit, independent of the weight parameter to < 0.1 mm)
and a female body is 14.0 cm shorter than a male one at the same parameter, so the height box is
the smallest round one in which both genders cover 150-200 cm. Weight keeps Anny's full axis. Muscle
is fixed at 0.25 rather than the neutral 0.5 because Anny's weight blendshapes are much weaker at
high muscle: at 0.5 the whole weight axis spans only BMI ~16-26; at 0.25 it spans ~17-33 (male).
A request is supported when its height is reachable at every weight parameter of the box
(``supported_height_range_cm``) and its mass lies between the lightest and heaviest box bodies of
that height (``supported_weight_range_kg``); anything else raises ``ShapeOutOfRange``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from service.geometry.mesh import check_mesh, signed_volume
from service.geometry.mesh_topology import frozen
from service.geometry.rings import dilate, vertex_neighbours
from service.geometry.self_contact import self_crossings
from service.pipeline.appearance import DisplayMesh
from service.process.paths import models_dir

BETA_LABELS = ("gender", "height", "weight")
DEFAULT_BETA = (0.5, 0.5, 0.5)
# The extended shape (issue 55, decision 0020): the three phenotypes extrapolated past Anny's anchors,
# plus these local changes (MakeHuman's girth targets, signed, exported by ``python -m export.body``).
LOCAL_NAMES = ("waist", "hips", "bust", "thigh", "upperarm", "belly")
SHAPE_LABELS = BETA_LABELS + LOCAL_NAMES
# Bounds of the extended shape. Height: 140-205 cm in both sexes with room (women 122 cm at 0, men
# 224 cm at 0.8). Weight: past ~2.5 Anny's surface folds and self-intersects (decision 0020). Local
# changes: the study's fits of 120 NHANES adults used -1.5..2.6; a margin on both sides.
SHAPE_BOUNDS = ((0.0, 1.0), (-0.1, 0.85), (-0.5, 2.5)) + ((-2.0, 3.0),) * len(LOCAL_NAMES)
BODY_DENSITY_KG_M3 = 1010.0
# Anny's bodies cross themselves between the toes (46 triangle pairs) and at a man's eyelids (2); those
# faces and this many rings around them (heavier bodies' toes cross a little further) are not pressed
# or counted.
TEMPLATE_CROSSING_RINGS = 3
SUPPORTED_HEIGHT_PARAM = (0.12, 0.72)
SUPPORTED_WEIGHT_PARAM = (0.0, 1.0)
# Newton stops when both residuals are below these (far below what a garment fit can notice).
HEIGHT_TOLERANCE_M = 1e-6
MASS_TOLERANCE_KG = 1e-5
MAX_NEWTON_STEPS = 30
# Decimals of the range bounds in refusal messages (0.1 cm, 0.1 kg: a tape measure and a scale's reading).
RANGE_DECIMALS = 1


class ShapeOutOfRange(ValueError):
    """A human-unit body request that is not a finite number or lies outside the supported range.

    field: the offending request field (``"gender"``, ``"height_cm"`` or ``"weight_kg"``).
    allowed: the allowed ``(low, high)`` for this request, or None for a non-finite value.
    """

    def __init__(self, field: str, message: str, allowed: tuple[float, float] | None = None):
        super().__init__(message)
        self.field = field
        self.allowed = allowed


# ---------------------------------------------------------------- pure math


def hat_coefficients(x: np.ndarray, anchors: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation coefficients, Anny's ``linear_interpolation_coefficients``.

    x: (B,) float, clamped to the anchor range. anchors: (n,) increasing.
    Returns (B, n) float64; each row has at most two non-zeros summing to 1. A value on an inner
    anchor belongs to the segment on its left, as in Anny.
    """
    coeffs, _ = _hat_segments(x, anchors)
    return coeffs


def hat_slopes(x: np.ndarray, anchors: np.ndarray) -> np.ndarray:
    """d hat_coefficients / dx ``(B, n)``, taken on the same segment as ``hat_coefficients``
    (one-sided at the ends and at inner anchors)."""
    _, slopes = _hat_segments(x, anchors)
    return slopes


def _hat_segments(
    x: np.ndarray, anchors: np.ndarray, extrapolate: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients and slopes; with ``extrapolate`` a value past an end anchor continues the end
    segment linearly (Anny's ``extrapolate_phenotypes``: coefficients below 0 and above 1)."""
    anchors = np.asarray(anchors, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    if not extrapolate:
        x = np.clip(x, anchors[0], anchors[-1])
    n = len(anchors)
    upper = np.clip(np.searchsorted(anchors, x, side="left"), 1, n - 1)
    width = anchors[upper] - anchors[upper - 1]
    alpha = (x - anchors[upper - 1]) / width
    rows = np.arange(len(x))
    coeffs = np.zeros((len(x), n))
    coeffs[rows, upper - 1] = 1.0 - alpha
    coeffs[rows, upper] = alpha
    slopes = np.zeros((len(x), n))
    slopes[rows, upper - 1] = -1.0 / width
    slopes[rows, upper] = 1.0 / width
    return coeffs, slopes


def corner_weights(betas: np.ndarray, anchors: tuple[np.ndarray, ...]) -> np.ndarray:
    """Multilinear weights ``(B, C)`` of the C = prod(len(anchors)) corner bodies, corner order
    ``(gender, height, weight)`` row-major, for betas ``(B, 3)``; rows sum to 1."""
    a = [hat_coefficients(betas[:, k], anchors[k]) for k in range(3)]
    return np.einsum("bi,bj,bk->bijk", *a).reshape(len(betas), -1)


def corner_weights_and_jacobian(
    betas: np.ndarray, anchors: tuple[np.ndarray, ...]
) -> tuple[np.ndarray, np.ndarray]:
    """Corner weights ``(B, C)`` and their derivatives w.r.t. beta ``(B, 3, C)`` for betas
    ``(B, 3)`` (one-sided at anchors)."""
    a, s = zip(*(_hat_segments(betas[:, k], anchors[k]) for k in range(3)), strict=True)
    rows = [
        np.einsum("bi,bj,bk->bijk", s[0], a[1], a[2]),
        np.einsum("bi,bj,bk->bijk", a[0], s[1], a[2]),
        np.einsum("bi,bj,bk->bijk", a[0], a[1], s[2]),
    ]
    weights = np.einsum("bi,bj,bk->bijk", *a).reshape(len(betas), -1)
    return weights, np.stack(rows, axis=1).reshape(len(betas), 3, -1)


def blend_corners(weights: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Vertices ``(B, V, 3)`` from corner weights ``(B, C)`` and corner bodies ``(C, V, 3)``."""
    # einsum, not BLAS: a (1, 12) x (12, 3V) gemm wakes OpenBLAS's thread pool, which on a busy
    # 2-core host costs ~10 ms instead of ~0.2 ms; for large batches both run at the same speed.
    flat = np.einsum("bc,cv->bv", weights, corners.reshape(len(corners), -1))
    return flat.reshape(len(weights), *corners.shape[1:])


def volume_tensor(corners: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Symmetric ``(C, C, C)`` tensor T with ``mesh_volume(blend_corners(w)) = T(w, w, w)``.

    corners: (C, V, 3) float64 corner bodies; faces: (F, 3) int, shared by all corners.
    The signed volume sum_f v0 . (v1 x v2) / 6 is trilinear in the vertices, hence cubic in w.
    """
    c = len(corners)
    v0 = corners[:, faces[:, 0]].reshape(c, -1)  # (C, 3F)
    v2 = corners[:, faces[:, 2]]  # (C, F, 3)
    t = np.empty((c, c, c))
    for j in range(c):
        cross = np.cross(corners[j, faces[:, 1]], v2)  # (C, F, 3): v1 of corner j x v2 of each corner
        t[:, j, :] = v0 @ cross.reshape(c, -1).T / 6.0
    perms = ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0))
    return sum(t.transpose(p) for p in perms) / 6.0


def extreme_vertex_candidates(corner_z: np.ndarray) -> np.ndarray:
    """Indices ``(K,)`` of the only vertices that can be the highest or lowest of a blend.

    corner_z: (C, V) corner z coordinates. Blend weights are non-negative, so a vertex below the top
    vertex of some corner at every corner is never the top of any blend (likewise for the bottom);
    dropping those leaves a handful, which makes the z extent cheap to evaluate.
    """
    keep = np.zeros(corner_z.shape[1], dtype=bool)
    for z in (corner_z, -corner_z):
        top = np.ones_like(keep)
        for ref in np.unique(np.argmax(z, axis=1)):
            top &= np.any(z >= z[:, ref : ref + 1], axis=0)
        keep |= top
    return np.flatnonzero(keep)


def height_and_gradient(
    weights: np.ndarray, weight_jacobian: np.ndarray, corner_z: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Z extent ``(B,)`` of the blended bodies and its gradient ``(B, 3)`` w.r.t. beta.

    weights: (B, C); weight_jacobian: (B, 3, C); corner_z: (C, K) corner z coordinates of all
    vertices or of a subset holding every possible extreme (``extreme_vertex_candidates``).
    """
    z = weights @ corner_z  # (B, V)
    rows = np.arange(len(z))
    top, bottom = np.argmax(z, axis=1), np.argmin(z, axis=1)
    span = corner_z[:, top] - corner_z[:, bottom]  # (C, B)
    return z[rows, top] - z[rows, bottom], np.einsum("bkc,cb->bk", weight_jacobian, span)


def volume_and_gradient(
    weights: np.ndarray, weight_jacobian: np.ndarray, tensor: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Enclosed volume ``(B,)`` and its gradient ``(B, 3)`` w.r.t. beta from the cubic form.

    weights: (B, C); weight_jacobian: (B, 3, C); tensor: (C, C, C) symmetric (``volume_tensor``).
    """
    tww = np.einsum("abc,nb,nc->na", tensor, weights, weights)  # (B, C)
    return np.einsum("na,na->n", tww, weights), 3.0 * np.einsum("nka,na->nk", weight_jacobian, tww)


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Enclosed volume in m^3 of a closed mesh: vertices (V, 3) float, faces (F, 3) int."""
    check_mesh(vertices, faces)
    return signed_volume(np.asarray(vertices, dtype=np.float64), np.asarray(faces))


def body_measurements(vertices: np.ndarray, faces: np.ndarray) -> tuple[float, float]:
    """(height_m, mass_kg) of a rest-pose body: z extent, and volume x BODY_DENSITY_KG_M3.

    The reference for ``BodyModel.height_mass``. vertices (V, 3) float, faces (F, 3) int.
    """
    volume = mesh_volume(vertices, faces)
    z = np.asarray(vertices)[:, 2]
    return float(z.max() - z.min()), volume * BODY_DENSITY_KG_M3


def display_mesh(faces: np.ndarray, face_uv: np.ndarray, uv: np.ndarray) -> DisplayMesh:
    """The display mesh of per-corner texture coordinates: ``faces (F, 3)`` vertex and ``face_uv (F, 3)``
    texture-coordinate indices into ``uv (T, 2)`` (OBJ convention, origin bottom left); one display
    vertex per distinct (vertex, texture coordinate) pair, UVs flipped to glTF's (origin top left)."""
    key = faces.reshape(-1).astype(np.int64) * len(uv) + face_uv.reshape(-1)
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    corner_uv = uv[face_uv.reshape(-1)[first]].astype(np.float32)
    flipped = np.stack([corner_uv[:, 0], 1.0 - corner_uv[:, 1]], axis=1)
    display = DisplayMesh(faces.reshape(-1)[first].astype(np.int64), flipped, inverse.reshape(faces.shape))
    display.check(int(faces.max()) + 1, faces)
    return display


def check_betas(betas: np.ndarray, batched: bool = True) -> np.ndarray:
    """Return betas as float64, raising ValueError unless ``(B, 3)`` (or ``(3,)`` when not
    batched), finite and within Anny's [0, 1]."""
    arr = np.asarray(betas, dtype=np.float64)
    want = (arr.ndim == 2 and arr.shape[1] == 3) if batched else arr.shape == (3,)
    if not want:
        shape = "(B, 3)" if batched else "(3,)"
        raise ValueError(f"beta must be {shape} (gender, height, weight), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("beta must be finite")
    bad = np.flatnonzero(np.any((arr < 0.0) | (arr > 1.0), axis=tuple(range(arr.ndim - 1))))
    if bad.size:
        names = ", ".join(BETA_LABELS[k] for k in bad)
        raise ValueError(f"beta must lie in [0, 1] (Anny phenotype units); out of range: {names}")
    return arr


def shape_coefficients(
    shapes: np.ndarray, anchors: tuple[np.ndarray, ...], n_local: int
) -> tuple[np.ndarray, np.ndarray]:
    """Basis coefficients ``u (B, K)`` and their Jacobian ``(B, S, K)`` of extended shapes ``(B, S)``,
    S = 3 + n_local, K = C + 2 n_local: the C corner weights (extrapolated hats), then each local
    change's positive part, then its negative part, so ``vertices = sum_k u_k basis_k``."""
    a, s = zip(*(_hat_segments(shapes[:, k], anchors[k], extrapolate=True) for k in range(3)), strict=True)
    b = len(shapes)
    weights = np.einsum("bi,bj,bk->bijk", *a).reshape(b, -1)
    c = weights.shape[1]
    jac = np.zeros((b, 3 + n_local, c + 2 * n_local))
    jac[:, 0, :c] = np.einsum("bi,bj,bk->bijk", s[0], a[1], a[2]).reshape(b, -1)
    jac[:, 1, :c] = np.einsum("bi,bj,bk->bijk", a[0], s[1], a[2]).reshape(b, -1)
    jac[:, 2, :c] = np.einsum("bi,bj,bk->bijk", a[0], a[1], s[2]).reshape(b, -1)
    local = shapes[:, 3:]
    rows = np.arange(n_local)
    # At exactly 0 the derivative is one-sided (the positive side): the fit starts there.
    jac[:, 3 + rows, c + rows] = local >= 0.0
    jac[:, 3 + rows, c + n_local + rows] = -(local < 0.0).astype(np.float64)
    return np.concatenate([weights, np.maximum(local, 0.0), np.maximum(-local, 0.0)], axis=1), jac


def check_shapes(shapes: np.ndarray, n_local: int, batched: bool = True) -> np.ndarray:
    """Return extended shapes as float64, raising ValueError unless ``(B, 3 + n_local)`` (or
    ``(3 + n_local,)``), finite and within ``SHAPE_BOUNDS``."""
    arr = np.asarray(shapes, dtype=np.float64)
    n = 3 + n_local
    if not ((arr.ndim == 2 and arr.shape[1] == n) if batched else arr.shape == (n,)):
        want = f"(B, {n})" if batched else f"({n},)"
        raise ValueError(f"shape must be {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("shape must be finite")
    lo, hi = np.array(SHAPE_BOUNDS[:n]).T
    bad = np.flatnonzero(np.any((arr < lo) | (arr > hi), axis=tuple(range(arr.ndim - 1))))
    if bad.size:
        raise ValueError(f"shape out of SHAPE_BOUNDS: {', '.join(SHAPE_LABELS[k] for k in bad)}")
    return arr


# ---------------------------------------------------------------- the model


@dataclass(frozen=True, eq=False)
class BodyModel:
    """Corner bodies of the runtime Anny shape space and what is derived from them.

    corners: (C, V, 3) float64, C = 2 x 2 x 3 bodies at the (gender, height, weight) anchors.
    anchors: the gender (2,), height (2,) and weight (3,) anchors.
    faces: (F, 3) int64, watertight and outward oriented.
    regions: (V,) uint8 index into ``region_names`` (body part of the strongest skinning bone).
    bone_names, bone_heads: (J,) names and (J, 3) float64 joint positions at ``DEFAULT_BETA``.
    display: Anny's UVs as a display mesh over ``faces`` (None in a file exported without them).
    metadata: fixed phenotypes, topology and Anny version the file was exported with.
    local_names, local_deltas: (L,) names and (L, 2, V, 3) float64 displacements of the local changes
    at +1 and -1 (an older file without them has L = 0).
    """

    corners: np.ndarray = field(repr=False)
    anchors: tuple[np.ndarray, np.ndarray, np.ndarray]
    faces: np.ndarray = field(repr=False)
    regions: np.ndarray = field(repr=False)
    region_names: tuple[str, ...]
    bone_names: tuple[str, ...] = field(repr=False)
    bone_heads: np.ndarray = field(repr=False)
    metadata: dict = field(default_factory=dict)
    display: DisplayMesh | None = field(default=None, repr=False)
    local_names: tuple[str, ...] = ()
    local_deltas: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 0, 3)), repr=False)
    extreme_z: np.ndarray = field(init=False, repr=False)  # (C, K) z of the possible extremes
    volume_tensor: np.ndarray = field(init=False, repr=False)  # (C, C, C)

    def __post_init__(self) -> None:
        corner_z = self.corners[:, :, 2]
        object.__setattr__(self, "extreme_z", corner_z[:, extreme_vertex_candidates(corner_z)])
        object.__setattr__(self, "volume_tensor", volume_tensor(self.corners, self.faces))

    @classmethod
    def load(cls, path: Path | str | None = None) -> BodyModel:
        """Load ``anny_shape.npz`` (default ``models_dir()/body/anny_shape.npz``)."""
        path = Path(path) if path is not None else models_dir() / "body" / "anny_shape.npz"
        if not path.exists():
            raise FileNotFoundError(f"{path} not found; build it with `python -m export.body`")
        with np.load(path, allow_pickle=False) as npz:
            data = {k: npz[k] for k in npz.files}
        anchors = tuple(data[f"anchors_{label}"].astype(np.float64) for label in BETA_LABELS)
        grid = data["corner_vertices"]
        if grid.shape[:3] != tuple(len(a) for a in anchors) or grid.shape[-1] != 3:
            raise ValueError(f"{path}: corner_vertices {grid.shape} does not match the anchors")
        corners = grid.astype(np.float64).reshape(-1, *grid.shape[3:])
        faces = frozen(np.ascontiguousarray(data["faces"], dtype=np.int64))
        check_mesh(corners[0], faces)
        metadata = {
            "fixed_phenotypes": dict(
                zip(
                    data["fixed_phenotype_names"].tolist(),
                    data["fixed_phenotype_values"].tolist(),
                    strict=True,
                )
            ),
            "topology": str(data["topology"]),
            "anny_version": str(data["anny_version"]),
        }
        return cls(
            corners=corners,
            anchors=anchors,
            faces=faces,
            regions=data["regions"],
            region_names=tuple(data["region_names"].tolist()),
            bone_names=tuple(data["bone_names"].tolist()),
            bone_heads=data["bone_heads"].astype(np.float64),
            metadata=metadata,
            display=display_mesh(faces, data["face_uv"], data["uv"]) if "uv" in data else None,
            **_local_changes(path, data),
        )

    @property
    def n_vertices(self) -> int:
        return self.corners.shape[1]

    @property
    def n_local(self) -> int:
        return len(self.local_names)

    @cached_property
    def basis(self) -> np.ndarray:
        """``(K, V, 3)``: the corner bodies, then the local changes at +1, then at -1."""
        deltas = self.local_deltas
        return np.concatenate([self.corners, deltas[:, 0], deltas[:, 1]]) if len(deltas) else self.corners

    @cached_property
    def shape_volume_tensor(self) -> np.ndarray:
        """``(K, K, K)``: ``volume_tensor`` of ``basis`` (~1 s, made on first use)."""
        return volume_tensor(self.basis, self.faces)

    @cached_property
    def template_crossings(self) -> np.ndarray:
        """``(F,) bool``: the faces where Anny's own bodies of average height and weight already cross
        themselves (between the toes; the male eyelids), ``TEMPLATE_CROSSING_RINGS`` rings around: what
        ``self_contact`` leaves as it is."""
        marked = np.zeros(self.n_vertices, dtype=bool)
        for gender in (0.0, 0.5, 1.0):
            body = self.vertices(np.array([gender, DEFAULT_BETA[1], DEFAULT_BETA[2]]))
            marked[self.faces[self_crossings(body, self.faces)].ravel()] = True
        marked = dilate(marked, vertex_neighbours(self.faces, self.n_vertices), TEMPLATE_CROSSING_RINGS)
        return frozen(marked[self.faces].any(axis=1))

    def as_shape(self, beta: np.ndarray) -> np.ndarray:
        """The extended shape ``(3 + L,)`` of beta ``(3,)``: no local change."""
        return np.concatenate([check_betas(beta, batched=False), np.zeros(self.n_local)])

    def shape_vertices(self, shape: np.ndarray) -> np.ndarray:
        """Rest vertices ``(V, 3)`` float64 of one extended shape ``(3 + L,)``."""
        return self.shape_vertices_batch(check_shapes(shape, self.n_local, batched=False)[None])[0]

    def shape_vertices_batch(self, shapes: np.ndarray) -> np.ndarray:
        """Rest vertices ``(B, V, 3)`` float64 of extended shapes ``(B, 3 + L)``."""
        shapes = check_shapes(shapes, self.n_local)
        u, _ = shape_coefficients(shapes, self.anchors, self.n_local)
        return blend_corners(u, self.basis)

    def vertices(self, beta: np.ndarray) -> np.ndarray:
        """Rest vertices ``(V, 3)`` float64 in metres for one beta ``(3,)``."""
        return self.vertices_batch(check_betas(beta, batched=False)[None])[0]

    def vertices_batch(self, betas: np.ndarray) -> np.ndarray:
        """Rest vertices ``(B, V, 3)`` float64 in metres for betas ``(B, 3)``."""
        betas = check_betas(betas)
        return blend_corners(corner_weights(betas, self.anchors), self.corners)

    def height_mass(self, betas: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Height m ``(B,)``, mass kg ``(B,)`` and their Jacobian ``(B, 2, 3)`` w.r.t. betas
        ``(B, 3)``, exactly as ``body_measurements`` on ``vertices_batch`` (no mesh is built)."""
        betas = check_betas(betas)
        w, dw = corner_weights_and_jacobian(betas, self.anchors)
        height, dheight = height_and_gradient(w, dw, self.extreme_z)
        volume, dvolume = volume_and_gradient(w, dw, self.volume_tensor)
        jac = np.stack([dheight, BODY_DENSITY_KG_M3 * dvolume], axis=1)
        return height, BODY_DENSITY_KG_M3 * volume, jac


def _local_changes(path: Path, data: dict) -> dict:
    if "local_deltas" not in data:
        return {}
    names = tuple(data["local_names"].tolist())
    if names != LOCAL_NAMES:
        raise ValueError(f"{path}: local changes {names} are not the service's {LOCAL_NAMES}")
    deltas = data["local_deltas"].astype(np.float64)
    if deltas.shape != (len(names), 2, *data["corner_vertices"].shape[3:]):
        raise ValueError(f"{path}: local_deltas {deltas.shape} does not match the corners")
    return {"local_names": names, "local_deltas": deltas}


# ---------------------------------------------------------------- human units


def printed_bounds(lo: float, hi: float) -> tuple[float, float]:
    """``(lo, hi)`` rounded inwards to ``RANGE_DECIMALS``: the lower bound up, the upper one down, so a
    check against ``(lo, hi)`` accepts both printed bounds and refuses a value one printed step beyond
    either."""
    scale = 10**RANGE_DECIMALS
    up, down = math.ceil(lo * scale), math.floor(hi * scale)
    up += up / scale < lo  # a float product a hair below the exact one
    down -= down / scale > hi
    return up / scale, down / scale


def format_range(lo: float, hi: float) -> str:
    """``"135.7-200.8"``: the printed bounds of ``(lo, hi)`` (``printed_bounds``)."""
    p_lo, p_hi = printed_bounds(lo, hi)
    return f"{p_lo:.{RANGE_DECIMALS}f}-{p_hi:.{RANGE_DECIMALS}f}"


def _number(name: str, value: float) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ShapeOutOfRange(name, f"{name}={value!r} is not a number") from None
    if not np.isfinite(x):
        raise ShapeOutOfRange(name, f"{name}={x} is not a finite number")
    return x


def _check_gender(gender: float) -> float:
    g = _number("gender", gender)
    if not 0.0 <= g <= 1.0:
        raise ShapeOutOfRange(
            "gender", f"gender={g:g} is outside the supported range 0-1 (0 male, 1 female)", (0.0, 1.0)
        )
    return g


def _weight_param_samples() -> np.ndarray:
    """Box ends and the weight anchors inside: height is convex piecewise-linear in the weight
    parameter between anchors, so its maximum over the box is at one of these."""
    lo, hi = SUPPORTED_WEIGHT_PARAM
    inner = [a for a in (0.0, 0.5, 1.0) if lo < a < hi]
    return np.array([lo, *inner, hi])


def supported_height_range_cm(model: BodyModel, gender: float) -> tuple[float, float]:
    """Heights (cm) reachable with a height parameter in the box at every box weight parameter."""
    g = _check_gender(gender)
    w = _weight_param_samples()
    h_lo, h_hi = SUPPORTED_HEIGHT_PARAM
    betas = np.concatenate(
        [np.stack([np.full_like(w, g), np.full_like(w, h), w], axis=1) for h in (h_lo, h_hi)]
    )
    height, _, _ = model.height_mass(betas)
    return 100.0 * float(height[: len(w)].max()), 100.0 * float(height[len(w) :].min())


def _check_height(model: BodyModel, g: float, height_cm: float) -> float:
    h = _number("height_cm", height_cm)
    lo, hi = supported_height_range_cm(model, g)
    if not lo <= h <= hi:
        raise ShapeOutOfRange(
            "height_cm",
            f"height_cm={h:g} is outside the supported range {format_range(lo, hi)} cm for gender={g:g}",
            (lo, hi),
        )
    return h


def _solve_height_param(model: BodyModel, g: float, weight_params: np.ndarray, height_m: float) -> np.ndarray:
    """Height parameters ``(B,)`` giving ``height_m`` at each weight parameter ``(B,)``."""
    betas = np.stack([np.full_like(weight_params, g), np.full_like(weight_params, 0.5), weight_params], 1)
    for _ in range(MAX_NEWTON_STEPS):
        height, _, jac = model.height_mass(betas)
        residual = height - height_m
        if np.all(np.abs(residual) < HEIGHT_TOLERANCE_M):
            return betas[:, 1]
        betas[:, 1] = np.clip(betas[:, 1] - residual / jac[:, 0, 1], 0.0, 1.0)
    raise RuntimeError(f"height calibration did not converge for gender={g}, height={height_m} m")


def _lightest_heaviest(model: BodyModel, g: float, height_cm: float) -> tuple[np.ndarray, np.ndarray]:
    """Height parameters ``(2,)`` and masses ``(2,)`` of the lightest and heaviest box bodies."""
    w = np.array(SUPPORTED_WEIGHT_PARAM, dtype=np.float64)
    hp = _solve_height_param(model, g, w, height_cm / 100.0)
    _, mass, _ = model.height_mass(np.stack([np.full_like(w, g), hp, w], axis=1))
    return hp, mass


def supported_weight_range_kg(model: BodyModel, gender: float, height_cm: float) -> tuple[float, float]:
    """Masses (kg) of the lightest and heaviest box bodies of this gender and height."""
    g = _check_gender(gender)
    _, mass = _lightest_heaviest(model, g, _check_height(model, g, height_cm))
    return float(mass[0]), float(mass[1])


def shape_from_measurements(
    model: BodyModel, gender: float, height_cm: float, weight_kg: float
) -> np.ndarray:
    """beta ``(3,)`` float64 whose body has exactly this height (cm) and mass (kg); gender in
    [0, 1] is passed through. Raises ShapeOutOfRange outside the supported range."""
    g = _check_gender(gender)
    h = _check_height(model, g, height_cm)
    m = _number("weight_kg", weight_kg)
    hp, (m_lo, m_hi) = _lightest_heaviest(model, g, h)
    if not m_lo <= m <= m_hi:
        raise ShapeOutOfRange(
            "weight_kg",
            f"weight_kg={m:g} is outside the supported range {format_range(m_lo, m_hi)} kg "
            f"for gender={g:g}, height_cm={h:g}",
            (m_lo, m_hi),
        )
    # Start on the straight line between the lightest and heaviest bodies of this height.
    t = (m - m_lo) / (m_hi - m_lo) if m_hi > m_lo else 0.5
    w_lo, w_hi = SUPPORTED_WEIGHT_PARAM
    beta = np.array([g, hp[0] + t * (hp[1] - hp[0]), w_lo + t * (w_hi - w_lo)])
    target = np.array([h / 100.0, m])
    for _ in range(MAX_NEWTON_STEPS):
        height, mass, jac = model.height_mass(beta[None])
        residual = np.array([height[0], mass[0]]) - target
        if abs(residual[0]) < HEIGHT_TOLERANCE_M and abs(residual[1]) < MASS_TOLERANCE_KG:
            return beta
        beta[1:] = np.clip(beta[1:] - np.linalg.solve(jac[0, :, 1:], residual), 0.0, 1.0)
    raise RuntimeError(f"shape calibration did not converge for {gender=}, {height_cm=}, {weight_kg=}")


def measurements_from_shape(model: BodyModel, beta: np.ndarray) -> tuple[float, float]:
    """(height_cm, weight_kg) of the body of beta ``(3,)``; inverse of ``shape_from_measurements``."""
    height, mass, _ = model.height_mass(check_betas(beta, batched=False)[None])
    return 100.0 * float(height[0]), float(mass[0])
