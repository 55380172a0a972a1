"""What a garment's geometry says about how it is worn, instead of its category (issue 54).

Read off the garment's ``layering.GarmentProfile`` on the mean body (its closed loops per level and
the body parts each wraps: torso, arm, leg), against two of the body's own levels (``BodyLevels``):
its crotch and its armpits. Pure functions of the slices the layering rule makes anyway, so an
imported garment of any category (``top``, ``bottom``, ``dress``) gets them too.

``GarmentTraits`` says where the garment is (its lowest and highest loops, the highest one around the
torso) and what it does there: whether it goes around each leg separately (pants, shorts), around an arm
alone (a sleeve cut long enough for a horizontal slice to close around it), covers the chest (its torso
loops reach ``CollisionSettings.chest`` of the way from the crotch to the armpits: a top, a dress; not a
bottom held at the waist) and hangs free below the hips (its hem goes around both legs in one loop: a
skirt, a dress). The category decisions of the collision stages are expressed over these:

- ``tucked``: a garment worn on the chest inside one worn from the waist down around the legs, whose
  hem is gathered up above the outer one's crotch (``junctions.raising``), never the outer one let
  down. Tops in bottoms; a dress in pants too (the layering rule refuses that order: the dress's skirt
  wraps both legs), not a top in a dress (the dress covers the chest: nothing is tucked into it).
- ``worn_alike``: both cover the chest or neither (a looser top under a tighter one, a bottom in
  another; a dress with the tops): ``squeeze.asks_segment_test``.

On the bundled catalog these give exactly the category rules they replace, for all 42 ordered pairs
(``tests/pipeline/test_traits.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

from service.pipeline.collisions.layering import BodySlices, GarmentProfile
from service.pipeline.collisions.settings import SETTINGS


@dataclass(frozen=True)
class BodyLevels:
    """The body's landmark heights (m, the slices' levels): ``crotch``, the highest level where the legs
    are apart, and ``armpit``, the top of the run of levels, from the hands up, where the arms are
    apart from the torso."""

    crotch: float
    armpit: float

    @classmethod
    def of(cls, body: BodySlices) -> BodyLevels:
        legs = [k for k, names in enumerate(body.names) if "leg" in names]
        arms = [k for k, names in enumerate(body.names) if "arm" in names]
        if not legs or not arms:
            raise ValueError("the body's slices have no legs or no arms apart")
        top = arms[0]
        while top + 1 < len(body.levels) and "arm" in body.names[top + 1]:
            top += 1  # up the arms to where they join the shoulders (not the head's side loops)
        return cls(float(body.levels[max(legs)]), float(body.levels[top]))

    @property
    def chest(self) -> float:
        """m: the level a garment's torso loops must reach to cover the chest (``SETTINGS.chest``)."""
        return self.crotch + SETTINGS.chest * (self.armpit - self.crotch)


@dataclass(frozen=True)
class GarmentTraits:
    """How a garment is worn, read off its profile on the mean body (heights in m, the body's levels;
    None where it has no such loop)."""

    garment_id: str
    lowest: float | None
    """The lowest level with a closed loop of the garment."""
    highest: float | None
    """The highest level with a closed loop of the garment."""
    torso_top: float | None
    """The highest level where a loop wraps the torso: a bottom's waistband, a top's armholes or
    shoulders, a strapless dress's neckline."""
    holds_legs_apart: bool
    """A loop around one leg alone somewhere (pants, shorts; not a skirt)."""
    has_sleeves: bool
    """A loop around one arm alone somewhere (the long sleeve's and the jacket's sleeves; a T-shirt's
    short sleeve is cut by the slices at a slant and never closes around the arm)."""
    wraps_legs: bool
    """A loop around a leg, alone or with the other, below the crotch."""
    covers_chest: bool
    """Its torso loops reach the body's ``BodyLevels.chest``: worn on the upper body (a top, a dress),
    not from the waist down."""
    hangs_free_below_hips: bool
    """Its lowest loops around the legs go around both together (a skirt, a dress; not pants, whose legs
    close at the crotch)."""

    @classmethod
    def of(cls, profile: GarmentProfile, body: BodySlices, levels: BodyLevels | None = None) -> GarmentTraits:
        levels = BodyLevels.of(body) if levels is None else levels
        at, torso, legs_apart, sleeves, legs = [], [], False, False, []
        for k, loops in enumerate(profile.loops):
            z = float(body.levels[k])
            for loop in loops:
                at.append(z)
                kinds = [body.names[k][i] for i in loop.parts]
                torso += [z] if "torso" in kinds else []
                one = len(kinds) == 1
                legs_apart |= one and kinds[0] == "leg"
                sleeves |= one and kinds[0] == "arm"
                if "leg" in kinds and z <= levels.crotch:  # both read off the same levels
                    legs.append((z, kinds.count("leg")))
        lowest_legs = min((z for z, _ in legs), default=None)
        return cls(
            garment_id=profile.garment_id,
            lowest=min(at, default=None),
            highest=max(at, default=None),
            torso_top=max(torso, default=None),
            holds_legs_apart=legs_apart,
            has_sleeves=sleeves,
            wraps_legs=bool(legs),
            covers_chest=bool(torso) and max(torso) >= levels.chest,
            hangs_free_below_hips=any(z == lowest_legs and n >= 2 for z, n in legs),
        )


def traits_of(rule, garment) -> GarmentTraits:
    """The traits of a catalog ``garment`` (``id``, ``vertices``, ``faces`` on the mean body) from a
    ``layering.LayeringRule``'s profile of it (made once by the rule, kept; the traits are a pass over
    its loops and the body's names, well under a millisecond)."""
    return GarmentTraits.of(rule.profile(garment), rule.body)


def tucked(inner: GarmentTraits, outer: GarmentTraits) -> bool:
    """Whether ``inner`` under ``outer`` is tucked in: worn on the chest, inside a garment worn from the
    waist down around the legs. Its hem, hidden under the outer garment, is gathered up above that
    one's crotch where it would hang below (``junctions.raising``) rather than the crotch let down."""
    return inner.covers_chest and not outer.covers_chest and outer.wraps_legs


def worn_alike(a: GarmentTraits, b: GarmentTraits) -> bool:
    """Whether two garments are worn on the same part of the body: both cover the chest (tops, a
    dress) or neither (bottoms)."""
    return a.covers_chest == b.covers_chest
