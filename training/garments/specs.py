"""The procedural catalog: what each garment is, in terms of the mean body's joints.

A garment is the offset surface of the mean body at distance ``ease`` (a level set of the body's
signed distance, so it cannot self-intersect), cut by ``Cut``s that open its neckline, sleeves,
waist and hems, keeping the connected piece around ``keep_near``. The skirt is the exception: it
hangs from the waist as a flared tube (``SkirtSpec``), not glued to the legs.
Positions are in metres in the Anny frame (Z up, body facing -Y, body's left at +X); joint
names are Anny bone names; ``{s}`` stands for the side, ``L`` (+X) or ``R``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Category = Literal["top", "bottom"]


@dataclass(frozen=True)
class Cut:
    """Remove the part of the surface on the positive side of a plane, near a limb.

    The plane goes through ``origin`` (a joint, or a point ``along`` the way from ``origin`` to
    ``toward``, plus ``offset``), with unit normal ``normal`` or, if None, the direction
    origin -> toward. Only points within ``radius`` of the limb axis polyline ``limb`` are removed
    (inf: everywhere), so a cut across an inclined arm cannot slice into the torso.
    The boundary loop it leaves is the opening called ``opening``.
    """

    opening: str
    origin: str
    toward: str | None = None
    along: float = 0.0
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    normal: tuple[float, float, float] | None = None
    limb: tuple[str, ...] = ()
    radius: float = float("inf")
    sides: tuple[str, ...] = ("",)


@dataclass(frozen=True)
class NeckCut:
    """Remove a tilted neckline: inside an elliptic cylinder around the neck joint and above a
    plane that is ``front_drop`` below the joint at the front and ``back_drop`` at the back."""

    opening: str = "neck"
    joint: str = "neck01"
    forward: float = -0.025  # the neck's centre lies in front of the joint (body faces -Y)
    radius_x: float = 0.09
    radius_y: float = 0.10
    front_drop: float = 0.06
    back_drop: float = 0.02
    sides: tuple[str, ...] = ("",)


@dataclass(frozen=True)
class GarmentSpec:
    """One catalog entry built as a cut offset surface of the mean body."""

    id: str
    name: str
    category: Category
    layer_rank: int
    ease: float  # offset from the body surface, m
    cuts: tuple = ()
    keep_near: str = "spine03"  # joint inside the piece that is kept
    smooth_iterations: int = 5


@dataclass(frozen=True)
class SkirtSpec:
    """A flared tube from the waist: rings whose radius covers the body (plus ``ease``), never
    shrinks going down, and widens by ``flare`` metres per metre below the hips."""

    id: str
    name: str
    category: Category
    layer_rank: int
    ease: float
    waist_z: float
    hem_z: float
    flare: float
    hip_z: float = 0.12
    smooth_iterations: int = 3


ARM = ("upperarm01.{s}", "lowerarm01.{s}", "wrist.{s}")
SIDES = ("L", "R")


def hem(z: float) -> Cut:
    """Horizontal hem: keep what is above height z (tops)."""
    return Cut(opening="hem", origin="root", offset=(0.0, 0.0, z), normal=(0.0, 0.0, -1.0))


def waist(z: float) -> Cut:
    """Horizontal waistband: keep what is below height z (bottoms)."""
    return Cut(opening="waist", origin="root", offset=(0.0, 0.0, z), normal=(0.0, 0.0, 1.0))


def sleeve(along_arm: float, radius: float = 0.12) -> Cut:
    """Sleeve end at a fraction of the way from the shoulder (0) to the elbow (1) to the wrist (2)."""
    if along_arm <= 1.0:
        a, b, t = "upperarm01.{s}", "lowerarm01.{s}", along_arm
    else:
        a, b, t = "lowerarm01.{s}", "wrist.{s}", along_arm - 1.0
    return Cut(opening="sleeve_{s}", origin=a, toward=b, along=t, limb=ARM, radius=radius, sides=SIDES)


def leg_hem(z: float) -> Cut:
    """Leg opening: keep what is above height z, per leg."""
    return Cut(
        opening="leg_{s}",
        origin="upperleg01.{s}",
        offset=(0.0, 0.0, z),
        normal=(0.0, 0.0, -1.0),
        limb=("upperleg01.{s}", "lowerleg01.{s}", "foot.{s}"),
        radius=0.16,
        sides=SIDES,
    )


def armhole(tilt_up: float = 0.45, inset: float = 0.035) -> Cut:
    """Sleeveless armhole: a plane facing outward and a little up, ``inset`` inside the shoulder."""
    return Cut(
        opening="armhole_{s}",
        origin="upperarm01.{s}",
        offset=(-inset, 0.0, 0.0),
        normal=(1.0, 0.0, tilt_up),
        limb=ARM,
        radius=0.16,
        sides=SIDES,
    )


CATALOG: tuple[GarmentSpec | SkirtSpec, ...] = (
    GarmentSpec(
        "tank_top", "Tank top", "top", 1, ease=0.006,
        cuts=(hem(-0.05), NeckCut(radius_x=0.10, radius_y=0.11, front_drop=0.13, back_drop=0.06), armhole()),
    ),
    GarmentSpec(
        "tshirt", "T-shirt", "top", 3, ease=0.014,
        cuts=(hem(-0.08), NeckCut(), sleeve(0.45)),
    ),
    GarmentSpec(
        "long_sleeve", "Long-sleeve shirt", "top", 4, ease=0.022,
        cuts=(hem(-0.10), NeckCut(radius_x=0.085, radius_y=0.095, front_drop=0.05), sleeve(1.92)),
    ),
    GarmentSpec(
        "jacket", "Jacket", "top", 5, ease=0.045,
        cuts=(hem(-0.11), NeckCut(radius_x=0.11, radius_y=0.12, front_drop=0.09, back_drop=0.01),
              sleeve(1.95, radius=0.16)),
        smooth_iterations=10,
    ),
    GarmentSpec(
        "pants", "Pants", "bottom", 2, ease=0.012,
        cuts=(waist(0.10), leg_hem(-0.86)), keep_near="upperleg01.L",
    ),
    GarmentSpec(
        "shorts", "Shorts", "bottom", 2, ease=0.018,
        cuts=(waist(0.10), leg_hem(-0.24)), keep_near="upperleg01.L",
    ),
    SkirtSpec("skirt", "Skirt", "bottom", 2, ease=0.02, waist_z=0.26, hem_z=-0.30, flare=0.25),
)
