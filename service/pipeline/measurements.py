"""A body's tape measurements, as a tailor takes them (ISO 8559-1:2017 names), read off its mesh.

Every girth is a horizontal tape around the torso (``service.geometry.girth``): the perimeter of
the convex hull of the torso's section at that height, the arms' sections left out (Anny's rest
pose is an A-pose, so below the armpits the arms are loops of their own). Heights are searched on
the 5 mm grid ``z = k * STEP_M`` (absolute, so a level on the grid is found exactly):

- ``waist_cm``, ISO 8559-1 *waist girth* at the *natural waistline*: the smallest torso girth
  between the top of the hip bones (the iliac crests) and the lowest ribs;
- ``hip_cm``, ISO 8559-1 *hip girth*: the girth at the buttocks' most prominent point, the height
  between the crotch and the iliac crests (the buttocks lie below them) where the torso's section
  reaches farthest back (+y:
  the body faces -y). Not the largest girth there: on Anny bodies that stays within 0.5 cm over 5-8 cm
  of height and its maximum landed a few cm below the buttocks, 1.5 cm above the crotch on the
  default body, where a tape would not sit;
- ``chest_cm``, ISO 8559-1 *chest girth* (men) or *bust girth* (women): the largest girth between the
  natural waistline and the armpits, i.e. across the shoulder blades and the chest's (the bust's)
  most prominent points, below where the arms join the torso;
- ``waist_iliac_cm``, the waist circumference of NHANES (CDC anthropometry procedures manual): the
  girth just above the iliac crests; lower than the natural waistline, so it reads more (below a
  belly, much more);
- ``height_cm`` (ISO 8559-1 *stature*: the mesh's z extent) and ``weight_kg`` (enclosed volume times
  ``BODY_DENSITY_KG_M3``), both as ``service.pipeline.body.body_measurements`` defines them, so a
  body from ``shape_from_measurements(height_cm, weight_kg)`` measures back those numbers.

Landmark heights (``landmarks``) come from Anny's skeleton, whose joints are known at
``DEFAULT_BETA`` only, so each is carried to any body of the same topology by a ring of torso
vertices around it (the ring's mean height moves with the body, the joint's offset from it is kept):

- iliac crests: the ``spine04`` joint, taken as L4, where the line joining the iliac crests' tops
  (Tuffier's line) crosses the spine: at the default body 9.4 cm above the hip joints
  (``upperleg01``) and at 0.58 of the stature from the floor;
- lowest ribs: the ``spine02`` joint, taken as the thoracolumbar junction where the lowest ribs
  end: 0.67 of the stature (the default body's natural waist comes out at 0.65, inside the band);
- top of the chest search: the shoulder joints (``upperarm01``); the search stops lower, at the first
  height where the tape would go round an upper arm (the centre of that arm's vertices near that
  height lies inside the torso's hull): the armpits;
- crotch: the lowest vertex on the body's midline (x = 0) below the pelvis; heights where no torso
  loop goes round the torso's centre (between the legs) are skipped.

The torso's centre, which picks the torso's loop out of each section, is the mean (x, y) of Anny's
``torso`` region vertices.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from service.geometry.girth import encloses, tape_girths
from service.geometry.mesh import check_mesh
from service.pipeline.body import DEFAULT_BETA, BodyModel, body_measurements

STEP_M = 0.005  # the search grid of the landmark heights
RING_M = 0.01  # half-height of the vertex ring that carries a joint's height to other bodies
ARM_BAND_M = 0.01  # half-height of the arm vertices whose centre is the arm's at a height
MIDLINE_M = 1e-6  # |x| of a midline vertex
ILIAC_JOINT = "spine04"
RIB_JOINT = "spine02"
SHOULDER_JOINTS = ("upperarm01.L", "upperarm01.R")
PELVIS_JOINT = "pelvis.L"
TAPES = ("chest", "waist", "waist_iliac", "hip")


@dataclass(frozen=True, eq=False)
class Level:
    """A height carried by vertices: ``mean(z[vertices]) + offset`` (m)."""

    vertices: np.ndarray  # (R,) int
    offset: float

    def z(self, vertices: np.ndarray) -> float:
        return float(vertices[self.vertices, 2].mean() + self.offset)


@dataclass(frozen=True, eq=False)
class Landmarks:
    """Where to measure on any body of one topology (vertex indices, so any shape of it works).

    torso: (T,) vertices whose mean (x, y) is inside every torso section (picks the torso's loop).
    crotch: (M,) midline vertices below the pelvis; the lowest is the crotch.
    arms: upper-arm vertex sets (A_i,); the chest search stops where the tape goes round one.
    iliac, ribs, shoulders: the iliac crests', lowest ribs' and shoulder joints' heights.
    """

    torso: np.ndarray
    crotch: np.ndarray
    arms: tuple[np.ndarray, ...]
    iliac: Level
    ribs: Level
    shoulders: Level


@dataclass(frozen=True)
class BodyMeasurements:
    """A body's measurements (module docstring): height cm, weight kg and girths cm.

    levels_m: height (m, the mesh's frame) of each tape in ``TAPES``; tapes: where each lies, its
    hull's corners ``(H, 3)`` (a closed polyline at that height), for pictures."""

    height_cm: float
    weight_kg: float
    chest_cm: float
    waist_cm: float
    hip_cm: float
    waist_iliac_cm: float
    levels_m: dict[str, float] = field(default_factory=dict, repr=False, compare=False)
    tapes: dict[str, np.ndarray] = field(default_factory=dict, repr=False, compare=False)


def ring_level(vertices: np.ndarray, candidates: np.ndarray, z: float) -> Level:
    """The height z carried by the ``candidates`` vertices within RING_M of it."""
    ring = candidates[np.abs(vertices[candidates, 2] - z) <= RING_M]
    if not len(ring):
        raise ValueError(f"no vertex within {RING_M} m of the landmark height {z:g}")
    return Level(ring, float(z - vertices[ring, 2].mean()))


def landmarks(body: BodyModel) -> Landmarks:
    """The landmarks of Anny's topology (module docstring), found on the body at ``DEFAULT_BETA``
    whose skeleton ``body.bone_heads`` is."""
    v = body.vertices(np.array(DEFAULT_BETA))
    joint = dict(zip(body.bone_names, body.bone_heads, strict=True))
    region = {name: i for i, name in enumerate(body.region_names)}
    torso = np.flatnonzero(body.regions == region["torso"])
    midline = np.flatnonzero((np.abs(v[:, 0]) <= MIDLINE_M) & (v[:, 2] < joint[PELVIS_JOINT][2]))
    shoulder_z = float(np.mean([joint[name][2] for name in SHOULDER_JOINTS]))
    return Landmarks(
        torso=torso,
        crotch=midline,
        arms=tuple(np.flatnonzero(body.regions == region[name]) for name in ("upperarm_l", "upperarm_r")),
        iliac=ring_level(v, torso, float(joint[ILIAC_JOINT][2])),
        ribs=ring_level(v, torso, float(joint[RIB_JOINT][2])),
        shoulders=ring_level(v, torso, shoulder_z),
    )


def _grid(lo: float, hi: float) -> np.ndarray:
    """Heights ``k * STEP_M`` in [lo, hi]."""
    return np.arange(np.ceil(lo / STEP_M - 1e-9), np.floor(hi / STEP_M + 1e-9) + 1) * STEP_M


def _arm_centres(vertices: np.ndarray, arm: np.ndarray, zs: np.ndarray) -> np.ndarray:
    """Mean (x, y) ``(L, 2)`` of the arm's vertices within ARM_BAND_M of each height (NaN: none)."""
    near = np.abs(vertices[arm, 2][None, :] - zs[:, None]) <= ARM_BAND_M  # (L, A)
    count = near.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (near @ vertices[arm, :2]) / count[:, None]


def _pick(zs: np.ndarray, girths: np.ndarray, band: np.ndarray, largest: bool, name: str) -> int:
    """Index of the largest (smallest) finite girth at the heights where ``band``."""
    found = band & np.isfinite(girths)
    if not found.any():
        raise ValueError(f"no torso section to measure the {name} on")
    masked = np.where(found, girths, -np.inf if largest else np.inf)
    return int(np.argmax(masked) if largest else np.argmin(masked))


def measure(vertices: np.ndarray, faces: np.ndarray, marks: Landmarks) -> BodyMeasurements:
    """The measurements (module docstring) of the closed, outward-oriented rest body ``vertices (V, 3)``
    (metres, Z up), ``faces (F, 3)``, at the ``landmarks`` of its topology. Raises ValueError on bad
    input or a body whose landmarks are out of order."""
    check_mesh(vertices, faces)
    v = np.asarray(vertices, dtype=np.float64)
    height_m, mass_kg = body_measurements(v, faces)
    centre = v[marks.torso, :2].mean(axis=0)
    crotch = float(v[marks.crotch, 2].min())
    iliac, ribs, shoulders = (level.z(v) for level in (marks.iliac, marks.ribs, marks.shoulders))
    if not crotch < iliac < ribs < shoulders:
        raise ValueError(
            f"landmarks out of order: crotch {crotch:.3f}, iliac crests {iliac:.3f}, lowest ribs {ribs:.3f}, "
            f"shoulders {shoulders:.3f} m"
        )
    zs = _grid(crotch, shoulders)
    girths, hulls = tape_girths(v, faces, np.append(zs, iliac), centre)
    girths, hulls, iliac_girth, iliac_hull = girths[:-1], hulls[:-1], girths[-1], hulls[-1]
    if not np.isfinite(iliac_girth):
        raise ValueError(f"no torso section at the iliac crests' height {iliac:.3f} m")

    waist = _pick(zs, girths, (zs >= iliac) & (zs <= ribs), largest=False, name="natural waist")
    back = np.array([h[:, 1].max() if len(h) else np.nan for h in hulls])  # (L,) y of the rearmost point
    # Below the iliac crests: above them a heavy body's lower back can reach farther back than its
    # buttocks (a man of BMI 37 measured his hip 5 cm above the crests, 7 cm more than at the buttocks).
    hip = _pick(zs, back, zs <= iliac, largest=True, name="hip")
    # The armpits: the first height above the waist where the tape goes round an upper arm.
    chest_band = zs >= zs[waist]
    for arm in marks.arms:
        centres = _arm_centres(v, arm, zs)
        for i in np.flatnonzero(chest_band & np.isfinite(centres[:, 0])):
            if len(hulls[i]) >= 3 and encloses(hulls[i], centres[i]):
                chest_band &= zs < zs[i]
                break
    chest = _pick(zs, girths, chest_band, largest=True, name="chest")

    picked = {"chest": chest, "waist": waist, "hip": hip}
    levels = {name: float(zs[i]) for name, i in picked.items()} | {"waist_iliac": iliac}
    flat = {name: hulls[i] for name, i in picked.items()} | {"waist_iliac": iliac_hull}
    tapes = {name: np.column_stack([flat[name], np.full(len(flat[name]), levels[name])]) for name in TAPES}
    return BodyMeasurements(
        height_cm=100.0 * height_m,
        weight_kg=mass_kg,
        chest_cm=100.0 * float(girths[chest]),
        waist_cm=100.0 * float(girths[waist]),
        hip_cm=100.0 * float(girths[hip]),
        waist_iliac_cm=100.0 * float(iliac_girth),
        levels_m=levels,
        tapes=tapes,
    )


def measure_shape(body: BodyModel, beta: np.ndarray, marks: Landmarks | None = None) -> BodyMeasurements:
    """``measure`` of the rest body of beta ``(3,)``; ``marks`` defaults to ``landmarks(body)``."""
    return measure(body.vertices(beta), body.faces, marks if marks is not None else landmarks(body))
