"""How a garment fits (issue 56): its ease and strain by body region, pure array functions.

Regions, each a plane on the wearer's body (``region_planes``):

- ``chest``, ``waist``, ``hip``: horizontal at the levels the body's tape measurements were taken
  (``service.pipeline.measurements``; ISO 8559-1 chest or bust, natural waist, hip);
- ``waistband``: a bottom's, horizontal ``WAISTBAND_BELOW_M`` under its waist opening;
- ``thigh``: horizontal, ``THIGH_BELOW_CROTCH_M`` below the crotch, around the left leg (ISO 8559-1's
  thigh girth is taken just below the gluteal fold);
- ``upper_arm``: across the left upper arm at its middle, square to its axis (Anny's rest pose is
  an A-pose, so the arm is not vertical).

A girth is a tape around a section (``girth.convex_perimeter``): of the body's part there, or of a
garment's faces of that part (``face_parts``: the body part nearest each face of the template, so a
sleeve's faces are left out of the chest's section where an A-pose sleeve touches the torso).

- The **garment's girth** in a region is its rest shape's, cut for its size: the rest mesh laid on
  the size's chart body (``training.garments.grading``), at that body's planes (a finished garment's
  measurement, as a size chart lists it).
- **What is under it** is the tape over the wearer's body and every inner layer's section there,
  together: a jacket over a sweater has the sweater under it.
- **Ease** = the garment's girth - what is under it (cm; negative: smaller than what it must go round).
- **Strain** is the cloth's: per triangle, the largest principal stretch of the worn mesh against its
  rest shape, minus 1 (``principal_strain``).

A region counts for a garment only where the garment goes round it (``garment_section``): a tank top
has no upper arm, a skirt no thigh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from service.geometry.girth import convex_hull, convex_perimeter, encloses, section_loops, signed_area
from service.pipeline.strain import RestShape

REGIONS = ("chest", "waist", "waistband", "hip", "thigh", "upper_arm")
TORSO_REGIONS = ("chest", "waist", "hip")
ARM_PARTS = ("upperarm_l", "upperarm_r", "lowerarm_l", "lowerarm_r", "hand_l", "hand_r")
THIGH_BELOW_CROTCH_M = 0.04  # just below the gluteal fold on Anny's bodies (a few cm under the crotch)
WAISTBAND_BELOW_M = 0.02  # a bottom's waist: this far under its waistband's mean height
ARM_JOINTS = ("upperarm01.L", "lowerarm01.L")  # shoulder and elbow: the upper arm's axis
JOINT_RING = 40  # vertices nearest a joint on the default body carry it to others (it lies 3-6 cm in)
THIGH_BAND_M = 0.02  # left-thigh vertices this near the thigh's plane give its centre
COVER_BINS = 36  # directions (10 degrees apart) around a body section's centre
# Share of them a garment's section must reach to go round a region: a T-shirt's chest, its sleeves'
# faces left out, reaches ~80 %; a skirt round one thigh, ~50 %.
COVER_SHARE = 0.7
WINDING_MIN = 0.95  # a limb's garment section winds once round it (an arc by it: ~0.8 or less)


@dataclass(frozen=True)
class Plane:
    """A cutting plane: ``origin (3,)``, unit ``normal (3,)``, in-plane axes ``u (3,)``, ``v (3,)``;
    ``limb``: a limb's (its section is the loop round ``origin``), else the torso's."""

    origin: np.ndarray
    normal: np.ndarray
    u: np.ndarray
    v: np.ndarray
    limb: bool = False

    @classmethod
    def through(cls, origin: np.ndarray, normal: np.ndarray, limb: bool = False) -> Plane:
        n = np.asarray(normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        u = np.cross(n, helper)
        u /= np.linalg.norm(u)
        return cls(np.asarray(origin, dtype=np.float64), n, u, np.cross(n, u), limb)

    @classmethod
    def at_height(cls, z: float) -> Plane:
        return cls.through(np.array([0.0, 0.0, z]), np.array([0.0, 0.0, 1.0]))

    def frame(self, points: np.ndarray) -> np.ndarray:
        """``points (N, 3)`` in the plane's frame ``(N, 3)``: (u, v, height above the plane)."""
        rel = np.asarray(points, dtype=np.float64) - self.origin
        return rel @ np.column_stack([self.u, self.v, self.normal])


@dataclass(frozen=True, eq=False)
class Joint:
    """A skeleton joint carried to any body of Anny's topology: the mean of ``vertices (R,)`` plus
    ``offset (3,)`` (its offset on the default body, where Anny's skeleton is known)."""

    vertices: np.ndarray
    offset: np.ndarray

    def at(self, body: np.ndarray) -> np.ndarray:
        return np.asarray(body)[self.vertices].mean(axis=0) + self.offset


def joint(default_body: np.ndarray, position: np.ndarray) -> Joint:
    """The ``Joint`` at ``position (3,)`` on the default body ``(B, 3)``."""
    ring = np.argsort(np.linalg.norm(default_body - position, axis=1))[:JOINT_RING]
    return Joint(ring, np.asarray(position) - default_body[ring].mean(axis=0))


def region_planes(
    vertices: np.ndarray, levels_m: dict[str, float], torso_centre: np.ndarray, crotch_z: float,
    thigh_centre: np.ndarray, arm: tuple[Joint, Joint],
) -> dict[str, tuple[Plane, np.ndarray]]:  # fmt: skip
    """Each region's plane (module docstring) on a body ``vertices (B, 3)``, with the point ``(2,)``
    (plane axes) its body loop goes round. ``levels_m``: the tapes' heights
    (``BodyMeasurements.levels_m``); ``torso_centre (2,)``: (x, y) inside the torso; ``crotch_z``: m;
    ``thigh_centre (2,)``: (x, y) inside the left thigh; ``arm``: the shoulder and elbow joints."""
    out = {}
    for name in TORSO_REGIONS:
        plane = Plane.at_height(levels_m[name])
        out[name] = (plane, plane.frame(np.append(torso_centre, levels_m[name])[None])[0, :2])
    thigh = np.append(thigh_centre, crotch_z - THIGH_BELOW_CROTCH_M)
    out["thigh"] = (Plane.through(thigh, np.array([0.0, 0.0, 1.0]), limb=True), np.zeros(2))
    shoulder, elbow = (j.at(vertices) for j in arm)
    out["upper_arm"] = (Plane.through((shoulder + elbow) / 2, elbow - shoulder, limb=True), np.zeros(2))
    return out


def waistband_plane(waist_opening: np.ndarray, torso_centre: np.ndarray) -> tuple[Plane, np.ndarray]:
    """A bottom's waist: the plane ``WAISTBAND_BELOW_M`` under its waist opening ``(L, 3)``."""
    z = float(np.asarray(waist_opening)[:, 2].mean()) - WAISTBAND_BELOW_M
    plane = Plane.at_height(z)
    return plane, plane.frame(np.append(torso_centre, z)[None])[0, :2]


@dataclass(frozen=True)
class BodySection:
    """A body's section in a region's plane: its ``loops`` (each ``(K, 2)``, plane axes) and which of
    them is the region's (``index``: the outermost round the region's point)."""

    loops: list
    index: int

    @property
    def tape(self) -> np.ndarray:
        """The tape's corners ``(H, 2)`` round the region's loop."""
        return convex_hull(self.loops[self.index])


def body_section(vertices: np.ndarray, faces: np.ndarray, plane: Plane, around: np.ndarray) -> BodySection:
    """The closed body ``vertices (V, 3)``, ``faces (F, 3)`` cut by ``plane``; the region's loop is the
    outermost that goes round ``around (2,)``, or for a limb, where none does (a joint carried from
    the default body can fall just outside a thin arm), the loop nearest it. Raises ValueError where
    the plane misses the body or no loop goes round a torso's point."""
    loops = section_loops(plane.frame(vertices), faces, 0.0)
    around_it = [k for k, loop in enumerate(loops) if encloses(loop, around)]
    if around_it:
        return BodySection(loops, max(around_it, key=lambda k: abs(signed_area(loops[k]))))
    if not loops or not plane.limb:
        raise ValueError(f"no loop of the body's section goes round {tuple(np.round(around, 3))}")
    return BodySection(loops, int(np.argmin([np.linalg.norm(loop - around, axis=1).min() for loop in loops])))


def garment_section(
    vertices: np.ndarray, faces: np.ndarray, parts: np.ndarray, plane: Plane, body: BodySection
) -> np.ndarray | None:
    """A garment's section ``(N, 2)`` in a region's plane, None where it does not go round it.

    Kept: the section's segments nearer the region's body loop than any other loop of the body's
    section (a trouser leg's, not the other leg's; a sleeve's, not the torso's); at the torso, only
    faces of parts other than the arms (``parts (F,)``, ``face_parts``), so an A-pose sleeve touching
    the chest is not counted. It goes round a limb where the kept segments wind once round the limb's
    point (``WINDING_MIN``): a skirt's arc by one thigh does not; round the torso, where they reach
    ``COVER_SHARE`` of ``COVER_BINS`` directions (the armholes leave gaps)."""
    f = np.asarray(faces)
    if not plane.limb:
        f = f[~np.isin(parts, ARM_PARTS)]
    segments = section_segments(vertices, f, plane)
    if len(segments) < 3:
        return None
    ring = np.concatenate(body.loops)
    owner = np.repeat(np.arange(len(body.loops)), [len(loop) for loop in body.loops])
    segments = segments[owner[cKDTree(ring).query(segments.mean(axis=1))[1]] == body.index]
    if len(segments) < 3:
        return None
    points = segments.reshape(-1, 2)
    if plane.limb:
        return points if abs(winding(segments, np.zeros(2))) >= WINDING_MIN else None
    rel = points - body.loops[body.index].mean(axis=0)
    angle = np.arctan2(rel[:, 1], rel[:, 0])
    bins = np.unique(np.floor((angle + np.pi) / (2 * np.pi) * COVER_BINS).astype(int) % COVER_BINS)
    return points if len(bins) >= COVER_SHARE * COVER_BINS else None


def section_segments(vertices: np.ndarray, faces: np.ndarray, plane: Plane) -> np.ndarray:
    """The section of ``faces (F, 3)`` over ``vertices (V, 3)`` by ``plane``: one segment ``(S, 2, 2)``
    (plane axes) per face it crosses, from where the face's edges go down through it to where they
    come up, so the segments of a consistently oriented mesh chain head to tail. A face with a
    corner exactly in the plane counts that corner as above it."""
    local = plane.frame(vertices)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    above = local[:, 2][f] > 0  # (F, 3)
    crossing = above.any(axis=1) & ~above.all(axis=1)
    f, above = f[crossing], above[crossing]
    a, b = f, np.roll(f, -1, axis=1)  # edge k runs corner k -> k+1
    da, db = local[a, 2], local[b, 2]
    t = np.where(da != db, da / np.where(da != db, da - db, 1.0), 0.0)
    point = local[a, :2] + t[..., None] * (local[b, :2] - local[a, :2])  # (F, 3, 2)
    rows = np.arange(len(f))
    down = np.argmax(above & ~np.roll(above, -1, axis=1), axis=1)
    up = np.argmax(~above & np.roll(above, -1, axis=1), axis=1)
    return np.stack([point[rows, down], point[rows, up]], axis=1)


def winding(segments: np.ndarray, point: np.ndarray) -> float:
    """How many times ``segments (S, 2, 2)`` wind round ``point (2,)`` (signed; 1 for a loop
    round it, a fraction for an arc)."""
    p, q = segments[:, 0] - point, segments[:, 1] - point
    angle = np.arctan2(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0], np.einsum("sd,sd->s", p, q))
    return float(angle.sum() / (2 * np.pi))


def tape_cm(*sections: np.ndarray) -> float:
    """A tape round every point of ``sections`` (each ``(N_i, 2)``, metres) together, in cm."""
    points = [s for s in sections if s is not None and len(s)]
    return 100.0 * convex_perimeter(np.concatenate(points)) if points else 0.0


def face_parts(
    body_vertices: np.ndarray, regions: np.ndarray, region_names: tuple[str, ...],
    vertices: np.ndarray, faces: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """The body part (a name of ``region_names``) nearest each face ``(F,)`` of a garment
    ``vertices (V, 3)``, ``faces (F, 3)`` on the body ``body_vertices (B, 3)`` whose vertices are of
    parts ``regions (B,)``."""
    _, nearest = cKDTree(body_vertices).query(np.asarray(vertices)[np.asarray(faces)].mean(axis=1))
    return np.asarray(region_names, dtype=object)[np.asarray(regions)[nearest]]


def principal_strain(x: np.ndarray, rest: RestShape) -> np.ndarray:
    """Per triangle ``(F,)``: the largest principal stretch of ``x (V, 3)`` against ``rest`` minus 1
    (0.1: stretched 10 % along its most stretched direction; negative: shorter in every direction).
    The singular value of F = Ds Dm^-1 ``(3, 2)``, from C = F^T F ``(2, 2)`` in closed form."""
    x = np.asarray(x, dtype=np.float64)
    f = rest.faces
    ds = np.stack([x[f[:, 1]] - x[f[:, 0]], x[f[:, 2]] - x[f[:, 0]]], axis=2)  # (F, 3, 2)
    F = ds @ rest.dm_inv
    C = np.einsum("fki,fkj->fij", F, F)
    a, b, d = C[:, 0, 0], C[:, 0, 1], C[:, 1, 1]
    largest = 0.5 * (a + d) + np.sqrt(0.25 * (a - d) ** 2 + b * b)
    return np.sqrt(largest) - 1.0


@dataclass(frozen=True)
class Layer:
    """A garment as worn: ``vertices (V, 3)``, ``faces (F, 3)``, ``parts (F,)`` (``face_parts``) and
    its waist opening ``(L,)`` where it has one (a bottom's waistband)."""

    vertices: np.ndarray
    faces: np.ndarray
    parts: np.ndarray
    waist: np.ndarray | None = None


@dataclass(frozen=True)
class BodyRegions:
    """A body cut at every region (``region_planes``): ``vertices (B, 3)``, ``faces``, each region's
    plane and the point its loop goes round, and ``torso_centre (2,)`` for a waistband's plane."""

    vertices: np.ndarray
    faces: np.ndarray
    planes: dict
    torso_centre: np.ndarray

    def plane(self, region: str, layer: Layer | None = None) -> tuple[Plane, np.ndarray] | None:
        """A region's plane; ``waistband`` is the layer's own (None for a layer without a waist)."""
        if region != "waistband":
            return self.planes[region]
        if layer is None or layer.waist is None:
            return None
        return waistband_plane(layer.vertices[layer.waist], self.torso_centre)


def girths(
    body: BodyRegions, layer: Layer, under: tuple[Layer, ...] = ()
) -> dict[str, tuple[float, float, float]]:
    """For each region ``layer`` goes round: (its girth, the tape over the body alone, the tape over
    the body and the ``under`` layers there), cm; each body section is cut once."""
    out = {}
    for region in REGIONS:
        cut = body.plane(region, layer)
        if cut is None:
            continue
        plane, around = cut
        section = body_section(body.vertices, body.faces, plane, around)
        own = garment_section(layer.vertices, layer.faces, layer.parts, plane, section)
        if own is None:
            continue
        inner = [garment_section(u.vertices, u.faces, u.parts, plane, section) for u in under]
        skin = tape_cm(section.tape)
        out[region] = (tape_cm(own), skin, tape_cm(section.tape, *inner) if under else skin)
    return out


@dataclass(frozen=True, eq=False)
class RegionMarks:
    """Where a body of Anny's topology is cut (vertex indices, so any shape of it works): ``torso``
    (T,) whose mean (x, y) is inside every torso section, ``crotch`` (M,) midline vertices whose
    lowest is the crotch, ``thigh`` (H,) the left upper leg's, ``arm``: shoulder and elbow joints."""

    torso: np.ndarray
    crotch: np.ndarray
    thigh: np.ndarray
    arm: tuple[Joint, Joint]


def body_regions(
    vertices: np.ndarray, faces: np.ndarray, levels_m: dict[str, float], marks: RegionMarks
) -> BodyRegions:
    """A body ``vertices (B, 3)``, ``faces (F, 3)`` whose tapes lie at ``levels_m`` cut at every region."""
    v = np.asarray(vertices, dtype=np.float64)
    centre = v[marks.torso, :2].mean(axis=0)
    crotch = float(v[marks.crotch, 2].min())
    leg = v[marks.thigh]
    near = np.abs(leg[:, 2] - (crotch - THIGH_BELOW_CROTCH_M)) <= THIGH_BAND_M
    thigh = (leg[near] if near.any() else leg)[:, :2].mean(axis=0)
    return BodyRegions(v, faces, region_planes(v, levels_m, centre, crotch, thigh, marks.arm), centre)
