"""Software renderer for looking at bodies, garments and outfits: a numpy z-buffer, no GPU, no display.

Every mesh goes through one real z-buffer, so interpenetrating layers show as they are: where the body
pokes through a shirt, the skin patch is visible. Surfaces seen from behind (the inside of an open
garment through its neckline) are shaded in a darker tint of the mesh colour.

Frame: Anny's, metres, Z up, the body faces -Y. Orthographic views (image up is +Z except where noted):

    front          camera on -Y looking along +Y: we see the face; the body's left hand (+X) is on the
                   image's right.
    back           camera on +Y looking along -Y.
    side           camera on -X (the body's right side) looking along +X: the body faces image right.
    side_left      camera on +X (the body's left side) looking along -X: the body faces image left.
    three_quarter  camera front-right (azimuth 45 deg between -Y and -X), 10 deg above the horizon.

Pipeline: ``rasterize`` (vectorised, triangles batched by power-of-two bounding-box size) next to
``rasterize_reference`` (one triangle at a time, for the tests), then per-pixel interpolated vertex
normals, Lambert key light + headlight + ambient + a faint specular, 1-pixel outlines at silhouettes,
layer changes, front/back changes and depth jumps, and ``supersample``-times supersampling.

Timing (``python -m training.render --bench``, pinned to 2 CPU cores shared with other jobs, load ~3):
at 800x800 the Anny mean body (26.7k faces) takes 0.1-0.2 s with ``supersample=1`` and 0.4-0.9 s with
the default ``supersample=2``; the same body loop-subdivided to 107k faces 0.3-0.45 s and 0.5-1.3 s.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, get_args

import numpy as np

View = Literal["front", "back", "side", "side_left", "three_quarter"]
VIEWS: tuple[str, ...] = get_args(View)
# (azimuth, elevation) of the camera in degrees; azimuth 0 is the -Y side, +90 the -X side.
_CAMERAS = {
    "front": (0.0, 0.0),
    "back": (180.0, 0.0),
    "side": (90.0, 0.0),
    "side_left": (-90.0, 0.0),
    "three_quarter": (45.0, 10.0),
}

PALETTE: dict[str, tuple[float, float, float]] = {
    "skin": (0.87, 0.69, 0.57),
    "denim": (0.27, 0.42, 0.64),
    "brick": (0.76, 0.27, 0.24),
    "sage": (0.36, 0.59, 0.41),
    "mustard": (0.87, 0.69, 0.25),
    "plum": (0.53, 0.38, 0.66),
    "teal": (0.20, 0.58, 0.60),
    "orange": (0.93, 0.53, 0.24),
    "rose": (0.88, 0.55, 0.66),
    "charcoal": (0.33, 0.34, 0.38),
}
BACKGROUND = (0.96, 0.96, 0.96)
OUTLINE = (0.12, 0.12, 0.14)
# Fraction of the back-face colour relative to the front: dark enough to read as "inside".
BACK_TINT = 0.5


@dataclass
class MeshLayer:
    """One triangle mesh to draw.

    vertices: (V, 3) float, metres, Anny frame (Z up, body faces -Y); stored as float64.
    faces: (F, 3) int, indices into ``vertices``; stored as int64. Outward faces wind counter-clockwise.
    color: RGB in [0, 1].
    face_colors: (F, 3) RGB in [0, 1] per face, in place of ``color`` (a tension map); None: ``color``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    color: tuple[float, float, float]
    name: str = ""
    face_colors: np.ndarray | None = None

    def __post_init__(self):
        v = np.asarray(self.vertices)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0 or not np.issubdtype(v.dtype, np.number):
            raise ValueError(f"vertices must be a non-empty (V, 3) float array, got shape {v.shape}")
        v = v.astype(np.float64)
        if not np.all(np.isfinite(v)):
            raise ValueError("vertices must be finite")
        f = np.asarray(self.faces)
        if f.size == 0:
            f = f.reshape(0, 3)
        if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
            raise ValueError(f"faces must be an (F, 3) integer array, got shape {f.shape} dtype {f.dtype}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"faces index out of range [0, {len(v)}): min {f.min()}, max {f.max()}")
        c = np.asarray(self.color, dtype=np.float64)
        if c.shape != (3,) or not np.all((c >= 0) & (c <= 1)):
            raise ValueError(f"color must be 3 floats in [0, 1], got {self.color!r}")
        self.vertices, self.faces, self.color = v, f.astype(np.int64), tuple(float(x) for x in c)
        if self.face_colors is not None:
            fc = np.asarray(self.face_colors, dtype=np.float64)
            if fc.shape != (len(f), 3) or not np.all((fc >= 0) & (fc <= 1)):
                raise ValueError(f"face_colors must be ({len(f)}, 3) floats in [0, 1], got shape {fc.shape}")
            self.face_colors = fc


@dataclass
class Raster:
    """What a z-buffer pass leaves per pixel (H rows, W columns).

    face: (H, W) int64, index of the visible triangle, -1 where nothing covers the pixel centre.
    depth: (H, W) float64, depth of the visible surface (smaller is nearer), +inf where empty.
    bary: (H, W, 3) float64, barycentric coordinates of the pixel centre in ``face`` (0 where empty).
    """

    face: np.ndarray
    depth: np.ndarray
    bary: np.ndarray


def _check_triangles(xy: np.ndarray, depth: np.ndarray, height: int, width: int):
    xy = np.asarray(xy, dtype=np.float64)
    depth = np.asarray(depth, dtype=np.float64)
    if xy.ndim != 3 or xy.shape[1:] != (3, 2):
        raise ValueError(f"xy must be (F, 3, 2), got {xy.shape}")
    if depth.shape != xy.shape[:2]:
        raise ValueError(f"depth must be (F, 3) matching xy, got {depth.shape}")
    for name, n in (("height", height), ("width", width)):
        if int(n) != n or n < 1:
            raise ValueError(f"{name} must be a positive integer, got {n!r}")
    return xy, depth, int(height), int(width)


# Barycentrics may be this far below zero and still count as inside, so that a pixel centre lying
# exactly on an edge shared by two triangles is drawn by both (overlap) rather than by neither (a hole).
_INSIDE_EPS = 1e-9
# Largest candidate-pixel batch (triangles x bounding-box pixels) evaluated at once; bounds memory.
_BATCH = 1 << 21


def rasterize(xy: np.ndarray, depth: np.ndarray, height: int, width: int) -> Raster:
    """Z-buffer triangles into an image, vectorised.

    xy: (F, 3, 2) float, vertex positions in pixels: x to the right, y down; the centre of pixel
        (row r, column c) is at (c + 0.5, r + 0.5). A pixel belongs to a triangle when its centre does.
    depth: (F, 3) float, per-vertex depth, interpolated linearly (exact for orthographic cameras).
    Ties in depth go to the higher face index.

    Triangles are grouped by their bounding box rounded up to powers of two (bw x bh pixels); each
    group is evaluated as one (n, bw * bh) array of barycentrics, so the Python loop runs over a few
    dozen groups rather than over triangles.
    """
    xy, depth, height, width = _check_triangles(xy, depth, height, width)
    n_faces = len(xy)
    zbuf = np.full(height * width, np.inf)
    fbuf = np.full(height * width, -1, dtype=np.int64)
    if n_faces == 0:
        return Raster(fbuf.reshape(height, width), zbuf.reshape(height, width), np.zeros((height, width, 3)))

    # Pixel-centre bounding boxes, clipped to the image.
    x0 = np.clip(np.ceil(xy[..., 0].min(1) - 0.5), 0, width).astype(np.int64)
    x1 = np.clip(np.floor(xy[..., 0].max(1) - 0.5), -1, width - 1).astype(np.int64)
    y0 = np.clip(np.ceil(xy[..., 1].min(1) - 0.5), 0, height).astype(np.int64)
    y1 = np.clip(np.floor(xy[..., 1].max(1) - 0.5), -1, height - 1).astype(np.int64)
    bw, bh = x1 - x0 + 1, y1 - y0 + 1

    # Barycentric l_i and depth as affine functions of the offset (ox, oy) from the box corner:
    # l_i = a_i ox + b_i oy + c_i. Local offsets keep the numbers small, hence the error tiny.
    p = xy - np.stack([x0, y0], axis=-1)[:, None, :].astype(np.float64) - 0.5
    px, py = p[..., 0], p[..., 1]
    area2 = (px[:, 1] - px[:, 0]) * (py[:, 2] - py[:, 0]) - (px[:, 2] - px[:, 0]) * (py[:, 1] - py[:, 0])
    keep = (bw > 0) & (bh > 0) & (np.abs(area2) > 1e-12)
    coef = np.empty((n_faces, 3, 3))
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        coef[:, i, 0] = py[:, j] - py[:, k]
        coef[:, i, 1] = px[:, k] - px[:, j]
        coef[:, i, 2] = px[:, j] * py[:, k] - px[:, k] * py[:, j]
    coef /= np.where(keep, area2, 1.0)[:, None, None]
    zcoef = np.einsum("fi,fij->fj", depth, coef)

    # Group by power-of-two box size; one key per (log2 width, log2 height).
    lw = np.ceil(np.log2(np.maximum(bw, 1))).astype(np.int64)
    lh = np.ceil(np.log2(np.maximum(bh, 1))).astype(np.int64)
    key = lw * 64 + lh
    ids_all = np.flatnonzero(keep)
    order = ids_all[np.argsort(key[ids_all], kind="stable")]
    groups = np.split(order, np.flatnonzero(np.diff(key[order])) + 1)

    frag_pix, frag_z, frag_face = [], [], []
    for group in groups:
        if len(group) == 0:
            continue
        gw, gh = 1 << int(lw[group[0]]), 1 << int(lh[group[0]])
        ox = np.tile(np.arange(gw), gh).astype(np.float64)
        oy = np.repeat(np.arange(gh), gw).astype(np.float64)
        per_batch = max(1, _BATCH // (gw * gh))
        for start in range(0, len(group), per_batch):
            ids = group[start : start + per_batch]
            c = coef[ids]
            inside = (ox[None] < bw[ids, None]) & (oy[None] < bh[ids, None])
            for i in range(3):
                inside &= c[:, i, 0:1] * ox + c[:, i, 1:2] * oy + c[:, i, 2:3] >= -_INSIDE_EPS
            row, k = np.nonzero(inside)
            face = ids[row]
            pix = (y0[face] + oy[k].astype(np.int64)) * width + x0[face] + ox[k].astype(np.int64)
            zc = zcoef[face]
            z = zc[:, 0] * ox[k] + zc[:, 1] * oy[k] + zc[:, 2]
            np.minimum.at(zbuf, pix, z)
            # Fragments already behind the buffer can never win; drop them early.
            near = z <= zbuf[pix]
            frag_pix.append(pix[near])
            frag_z.append(z[near])
            frag_face.append(face[near])

    if frag_pix:
        pix, z, face = np.concatenate(frag_pix), np.concatenate(frag_z), np.concatenate(frag_face)
        win = z == zbuf[pix]
        np.maximum.at(fbuf, pix[win], face[win])

    # Barycentrics of the winners, from the same affine coefficients.
    covered = np.flatnonzero(fbuf >= 0)
    f = fbuf[covered]
    ox = (covered % width - x0[f]).astype(np.float64)
    oy = (covered // width - y0[f]).astype(np.float64)
    bary = np.zeros((height * width, 3))
    bary[covered] = coef[f, :, 0] * ox[:, None] + coef[f, :, 1] * oy[:, None] + coef[f, :, 2]
    return Raster(fbuf.reshape(height, width), zbuf.reshape(height, width), bary.reshape(height, width, 3))


def rasterize_reference(xy: np.ndarray, depth: np.ndarray, height: int, width: int) -> Raster:
    """Same contract as ``rasterize``, one triangle at a time with edge functions in absolute
    pixel coordinates. Slow; exists to hold the vectorised version to account in the tests."""
    xy, depth, height, width = _check_triangles(xy, depth, height, width)
    zbuf = np.full((height, width), np.inf)
    fbuf = np.full((height, width), -1, dtype=np.int64)
    bary = np.zeros((height, width, 3))
    for fi, (tri, z) in enumerate(zip(xy, depth, strict=True)):
        c0 = max(0, int(np.ceil(tri[:, 0].min() - 0.5)))
        c1 = min(width - 1, int(np.floor(tri[:, 0].max() - 0.5)))
        r0 = max(0, int(np.ceil(tri[:, 1].min() - 0.5)))
        r1 = min(height - 1, int(np.floor(tri[:, 1].max() - 0.5)))
        if c1 < c0 or r1 < r0:
            continue
        (ax, ay), (bx, by), (cx, cy) = tri
        area2 = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
        if abs(area2) <= 1e-12:
            continue
        gx, gy = np.meshgrid(np.arange(c0, c1 + 1) + 0.5, np.arange(r0, r1 + 1) + 0.5)
        l0 = ((bx - gx) * (cy - gy) - (cx - gx) * (by - gy)) / area2
        l1 = ((cx - gx) * (ay - gy) - (ax - gx) * (cy - gy)) / area2
        l2 = ((ax - gx) * (by - gy) - (bx - gx) * (ay - gy)) / area2
        zz = l0 * z[0] + l1 * z[1] + l2 * z[2]
        tile = (slice(r0, r1 + 1), slice(c0, c1 + 1))
        inside = (l0 >= -_INSIDE_EPS) & (l1 >= -_INSIDE_EPS) & (l2 >= -_INSIDE_EPS)
        wins = inside & (zz <= zbuf[tile])  # <=: later (higher-index) faces win ties
        zbuf[tile] = np.where(wins, zz, zbuf[tile])
        fbuf[tile] = np.where(wins, fi, fbuf[tile])
        bary[tile] = np.where(wins[..., None], np.stack([l0, l1, l2], -1), bary[tile])
    return Raster(fbuf, zbuf, bary)


@dataclass(frozen=True)
class Camera:
    """Orthographic camera. right, up, forward: (3,) unit vectors (forward points into the scene);
    center: (3,) world point at the image centre; extent: world length spanning the fitted area."""

    right: np.ndarray
    up: np.ndarray
    forward: np.ndarray
    center: np.ndarray
    extent: float


def view_axes(view: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(right, up, forward) unit vectors of a named view, each (3,) float64, right-handed with -forward."""
    if view not in _CAMERAS:
        raise ValueError(f"view must be one of {VIEWS}, got {view!r}")
    azimuth, elevation = np.radians(_CAMERAS[view])
    # Camera position direction; azimuth 0 is -Y (in front of the body), +90 deg is -X.
    eye = np.array(
        [-np.sin(azimuth) * np.cos(elevation), -np.cos(azimuth) * np.cos(elevation), np.sin(elevation)]
    )
    forward = -eye
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    return right, up, forward


def _check_layers(layers) -> list[MeshLayer]:
    if not isinstance(layers, list | tuple) or not layers:
        raise ValueError(f"layers must be a non-empty list of MeshLayer, got {type(layers).__name__}")
    for i, layer in enumerate(layers):
        if not isinstance(layer, MeshLayer):
            raise ValueError(f"layers[{i}] must be a MeshLayer, got {type(layer).__name__}")
    return list(layers)


def _check_size(size) -> int:
    if isinstance(size, bool) or not isinstance(size, int | np.integer) or size < 16:
        raise ValueError(f"size must be an integer >= 16, got {size!r}")
    return int(size)


def fit_camera(layers: list[MeshLayer], view: str = "front", margin: float = 0.05) -> Camera:
    """Camera for ``view`` whose image square holds every vertex of ``layers`` with ``margin``
    (fraction of the image side) on each side of the larger projected dimension."""
    layers = _check_layers(layers)
    right, up, forward = view_axes(view)
    if not 0 <= margin < 0.5:
        raise ValueError(f"margin must be in [0, 0.5), got {margin!r}")
    pts = np.concatenate([layer.vertices for layer in layers])
    u, v = pts @ right, pts @ up
    lo, hi = np.array([u.min(), v.min()]), np.array([u.max(), v.max()])
    mid = (lo + hi) / 2
    depth_mid = (pts @ forward).mean()
    center = mid[0] * right + mid[1] * up + depth_mid * forward
    extent = max(float((hi - lo).max()), 1e-9) / (1 - 2 * margin)
    return Camera(right, up, forward, center, extent)


# Corners whose smooth vertex normal is further than this from their face's normal are shaded flat:
# keeps box edges and cloth hems crisp while organic surfaces stay smooth.
_CREASE_COS = np.cos(np.radians(45.0))


def corner_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3, 3) unit shading normal at each face corner: the angle-weighted vertex normal (independent
    of how flat regions are triangulated), or the face normal where the two differ by more than
    45 degrees (a crease)."""
    tri = vertices[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-20)
    vn = np.zeros_like(vertices)
    for i in range(3):
        e1, e2 = tri[:, (i + 1) % 3] - tri[:, i], tri[:, (i + 2) % 3] - tri[:, i]
        cos = np.einsum("fj,fj->f", e1, e2) / np.maximum(
            np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1), 1e-20
        )
        angle = np.arccos(np.clip(cos, -1, 1))
        for axis in range(3):
            vn[:, axis] += np.bincount(faces[:, i], weights=angle * fn[:, axis], minlength=len(vertices))
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-20)
    corners = vn[faces]
    crease = np.einsum("fcj,fj->fc", corners, fn) < _CREASE_COS
    corners[crease] = np.broadcast_to(fn[:, None, :], corners.shape)[crease]
    return corners


def _outline_mask(layer_id: np.ndarray, back: np.ndarray, depth: np.ndarray, jump: float) -> np.ndarray:
    """(H, W) bool: of every pair of 4-neighbours that differ in layer (background is layer -1) or
    facing, the nearer pixel; and the nearer pixel of every pair more than ``jump`` apart in depth.
    depth: (H, W) float, finite, background far behind the scene."""
    fg = layer_id >= 0
    mask = np.zeros_like(fg)
    for axis in (0, 1):
        head = (slice(None, -1), slice(None)) if axis == 0 else (slice(None), slice(None, -1))
        tail = (slice(1, None), slice(None)) if axis == 0 else (slice(None), slice(1, None))
        differs = (layer_id[head] != layer_id[tail]) | (back[head] != back[tail])
        dz = depth[tail] - depth[head]
        mask[head] |= fg[head] & ((differs & (dz >= 0)) | (dz > jump))
        mask[tail] |= fg[tail] & ((differs & (dz <= 0)) | (dz < -jump))
    return mask


def render(
    layers: list[MeshLayer],
    view: str = "front",
    size: int = 800,
    *,
    camera: Camera | None = None,
    outline: bool = True,
    supersample: int = 2,
    background: tuple[float, float, float] = BACKGROUND,
) -> np.ndarray:
    """Render meshes through one z-buffer; returns a (size, size, 3) float64 RGB image in [0, 1].

    layers: meshes to draw, all in the Anny frame (see the module docstring).
    view: one of ``VIEWS``. camera: overrides the auto-fit of ``fit_camera(layers, view)`` (its axes
        must then match ``view_axes``); pass the same camera to compare renders of different meshes.
    outline: 1-pixel dark lines at silhouettes, layer boundaries, front/back-face boundaries and depth jumps.
    supersample: render at ``supersample * size`` and box-filter down (anti-aliasing).
    """
    layers = _check_layers(layers)
    size = _check_size(size)
    if camera is None:
        camera = fit_camera(layers, view)
    else:
        view_axes(view)  # validates view
    if isinstance(supersample, bool) or not isinstance(supersample, int | np.integer) or supersample < 1:
        raise ValueError(f"supersample must be a positive integer, got {supersample!r}")
    bg = np.asarray(background, dtype=np.float64)
    if bg.shape != (3,) or not np.all((bg >= 0) & (bg <= 1)):
        raise ValueError(f"background must be 3 floats in [0, 1], got {background!r}")

    n = size * int(supersample)
    scale = n / camera.extent
    verts = np.concatenate([layer.vertices for layer in layers])
    offsets = np.cumsum([0] + [len(layer.vertices) for layer in layers])
    faces = np.concatenate([layer.faces + o for layer, o in zip(layers, offsets, strict=False)])
    face_layer = np.repeat(np.arange(len(layers)), [len(layer.faces) for layer in layers])
    shading_normals = np.concatenate([corner_normals(layer.vertices, layer.faces) for layer in layers])

    rel = verts - camera.center
    sx = rel @ camera.right * scale + n / 2
    sy = n / 2 - rel @ camera.up * scale
    raster = rasterize(np.stack([sx, sy], -1)[faces], (rel @ camera.forward)[faces], n, n)

    tri = verts[faces]
    face_normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    face_back = face_normal @ camera.forward > 0

    img = np.broadcast_to(bg, (n, n, 3)).copy()
    hit = raster.face >= 0
    f = raster.face[hit]
    nrm = np.einsum("pi,pij->pj", raster.bary[hit], shading_normals[f])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-20)
    back = face_back[f]
    nrm[back] *= -1
    to_eye = -camera.forward
    key = -0.45 * camera.right + 0.65 * camera.up + 0.6 * to_eye
    key /= np.linalg.norm(key)
    half = (key + to_eye) / np.linalg.norm(key + to_eye)
    lambert = 0.3 + 0.55 * np.clip(nrm @ key, 0, None) + 0.3 * np.clip(nrm @ to_eye, 0, None)
    specular = 0.12 * np.clip(nrm @ half, 0, None) ** 40
    face_colors = np.concatenate([
        layer.face_colors if layer.face_colors is not None else np.tile(layer.color, (len(layer.faces), 1))
        for layer in layers
    ])  # fmt: skip
    base = face_colors[f] * np.where(back, BACK_TINT, 1.0)[:, None]
    img[hit] = np.clip(base * lambert[:, None] + np.where(back, 0, specular)[:, None], 0, 1)

    if outline:
        layer_id = np.full((n, n), -1, dtype=np.int64)
        layer_id[hit] = face_layer[f]
        back_map = np.zeros((n, n), dtype=bool)
        back_map[hit] = back
        depth = np.where(hit2d := raster.face >= 0, raster.depth, 0.0)
        depth[~hit2d] = depth.max() + 10 * camera.extent  # finite, far behind everything
        lines = _outline_mask(layer_id, back_map, depth, jump=0.02 * camera.extent)
        for _ in range(int(supersample) - 1):  # keep the line 1 output pixel wide
            lines[:, 1:] |= lines[:, :-1]
            lines[1:] |= lines[:-1]
        img[lines] = 0.15 * img[lines] + 0.85 * np.asarray(OUTLINE)

    if supersample > 1:
        ss = int(supersample)
        img = sum(img[i::ss, j::ss] for i in range(ss) for j in range(ss)) / ss**2
    return img


def _check_image(image, name: str = "image") -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] == 0 or img.shape[1] == 0:
        raise ValueError(f"{name} must be an (H, W, 3) RGB array, got shape {img.shape}")
    return np.clip(img.astype(np.float64), 0, 1)


def text_strip(text: str, width: int, height: int = 40, color=(0.1, 0.1, 0.1), background=BACKGROUND):
    """(height, width, 3) float image with ``text`` centred on it (matplotlib's Agg, no display)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    dpi = 100
    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor=background)
    canvas = FigureCanvasAgg(fig)
    fig.text(0.5, 0.5, text, ha="center", va="center", color=color, fontsize=0.42 * height * 72 / dpi)
    canvas.draw()
    rgb = np.asarray(canvas.buffer_rgba())[..., :3].astype(np.float64) / 255
    out = np.broadcast_to(np.asarray(background, dtype=np.float64), (height, width, 3)).copy()
    h, w = min(height, rgb.shape[0]), min(width, rgb.shape[1])  # Agg may round the canvas by a pixel
    out[:h, :w] = rgb[:h, :w]
    return out


def render_views(
    layers: list[MeshLayer],
    views: tuple[str, ...] | list[str] = ("front", "side"),
    size: int = 600,
    title: str | None = None,
    **render_kwargs,
) -> np.ndarray:
    """Views side by side, each (size, size), one scale for all; returns (H, size * len(views), 3),
    H = size plus a 40-pixel strip when ``title`` is given. ``render_kwargs`` go to ``render``."""
    layers = _check_layers(layers)
    size = _check_size(size)
    if isinstance(views, str) or not views:
        raise ValueError(f"views must be a non-empty sequence of view names, got {views!r}")
    cameras = [fit_camera(layers, v) for v in views]
    extent = max(c.extent for c in cameras)
    images = [
        render(layers, v, size, camera=Camera(c.right, c.up, c.forward, c.center, extent), **render_kwargs)
        for v, c in zip(views, cameras, strict=True)
    ]
    out = np.concatenate(images, axis=1)
    if title is not None:
        out = np.concatenate([text_strip(title, out.shape[1]), out], axis=0)
    return out


def grid(
    images: list[np.ndarray], titles: list[str] | None = None, columns: int = 3, gap: int = 8
) -> np.ndarray:
    """Tile (H_i, W_i, 3) images row by row into one (H, W, 3) image, each cell padded to the largest
    image with the background colour and topped by its title (a 32-pixel strip) when ``titles`` is given."""
    if not isinstance(images, list | tuple) or not images:
        raise ValueError("images must be a non-empty list of (H, W, 3) arrays")
    images = [_check_image(im, f"images[{i}]") for i, im in enumerate(images)]
    if titles is not None and len(titles) != len(images):
        raise ValueError(f"titles must have one entry per image ({len(images)}), got {len(titles)}")
    if isinstance(columns, bool) or not isinstance(columns, int | np.integer) or columns < 1:
        raise ValueError(f"columns must be a positive integer, got {columns!r}")
    if isinstance(gap, bool) or not isinstance(gap, int | np.integer) or gap < 0:
        raise ValueError(f"gap must be a non-negative integer, got {gap!r}")
    bg = np.asarray(BACKGROUND)
    ch, cw = max(im.shape[0] for im in images), max(im.shape[1] for im in images)
    cells = []
    for i, im in enumerate(images):
        cell = np.broadcast_to(bg, (ch, cw, 3)).copy()
        top, left = (ch - im.shape[0]) // 2, (cw - im.shape[1]) // 2
        cell[top : top + im.shape[0], left : left + im.shape[1]] = im
        if titles is not None:
            cell = np.concatenate([text_strip(str(titles[i]), cw, 32), cell], axis=0)
        padded = np.broadcast_to(bg, (cell.shape[0] + gap, cell.shape[1] + gap, 3)).copy()
        padded[gap // 2 : gap // 2 + cell.shape[0], gap // 2 : gap // 2 + cell.shape[1]] = cell
        cells.append(padded)
    columns = min(int(columns), len(cells))
    blank = np.broadcast_to(bg, cells[0].shape)
    cells += [blank] * (-len(cells) % columns)
    rows = [np.concatenate(cells[r : r + columns], axis=1) for r in range(0, len(cells), columns)]
    return np.concatenate(rows, axis=0)


def png_bytes(image: np.ndarray) -> bytes:
    """An (H, W, 3) float RGB image in [0, 1] (clipped) as 8-bit PNG bytes."""
    img = _check_image(image)
    data = (img * 255 + 0.5).astype(np.uint8)
    h, w, _ = data.shape
    raw = np.concatenate([np.zeros((h, 1), np.uint8), data.reshape(h, w * 3)], axis=1).tobytes()

    def chunk(tag: bytes, payload: bytes) -> bytes:
        return struct.pack(">I", len(payload)) + tag + payload + struct.pack(">I", zlib.crc32(tag + payload))

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    return png + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


def save_png(path: str | Path, image: np.ndarray) -> Path:
    """Write an (H, W, 3) float RGB image in [0, 1] (clipped) as an 8-bit PNG; creates parent folders."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(png_bytes(image))
    return path


def _bench(size: int = 800, repeats: int = 3) -> None:
    """Print render times of the Anny mean body, as is and loop-subdivided (~107k faces)."""
    import time

    import trimesh

    from training.anny_body import anny_faces, anny_rest

    vertices, faces = anny_rest(np.array([[0.5, 0.5, 0.5]])).vertices[0], anny_faces()
    meshes = {"anny": (vertices, faces), "anny x4": trimesh.remesh.subdivide(vertices, faces)}
    for name, (v, f) in meshes.items():
        layer = MeshLayer(v, f, PALETTE["skin"], name)
        for supersample in (1, 2):
            render([layer], "front", size, supersample=supersample)  # warm-up
            t0 = time.perf_counter()
            for _ in range(repeats):
                render([layer], "front", size, supersample=supersample)
            dt = (time.perf_counter() - t0) / repeats
            print(f"{name:8s} {len(f):7d} faces  {size}x{size}  supersample={supersample}  {dt:.2f} s")


if __name__ == "__main__":
    import sys

    if sys.argv[1:] != ["--bench"]:
        sys.exit("usage: python -m training.render --bench")
    _bench()
