"""Which size to buy (issue 56): each size's ease on the shopper, and the rule that picks one.

``models/garments/sizes.json`` (``python -m training.garments.grading``) holds, per style, its run
(``service.pipeline.sizes``) and, per size, the garment's girth in every region it goes round, measured
on the size's rest shape on its chart body (``service.pipeline.ease``): a finished garment's
measurements, as a shop's size table lists them. The style's *design ease* in a region is the ease of
its M on the M chart body (the garment the pattern was drawn as; a tank top fits at +4 cm, a jacket
hangs at +28, docs/fit.md).

On a shopper, a size's ease in a region is its girth minus the tape over her body, and over her body
and the layers under it there. The rule (``recommend``, ``RULE``):

1. A size *fits* where every region's ease over the body is at least its design ease minus
   ``EASE_TOLERANCE_CM``, half a chart step (a body at the top of a size's chart band still takes that
   size: the chart's choice, as a size table picks it), and, with layers under it, its ease over them
   is at least ``OVER_LAYERS_CM`` (it goes on over them: a jacket's 26 cm of design ease are meant
   for a shirt under it, so over a T-shirt the chart's size still fits, over a thick stack it may not).
2. The recommended size is the smallest that fits; none fitting, the largest, marked as not fitting,
   with the regions that do not.
3. The runner-up is the next size up when the recommended one fits by less than ``CLOSE_CM`` somewhere
   (roomier), else the next size down when that one misses by less than ``CLOSE_CM`` (closer), else none.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.ease import ARM_JOINTS, RegionMarks, joint
from service.pipeline.measurements import Landmarks
from service.process.paths import models_dir

SIZES_NAME = "sizes.json"
RULE = "smallest-size-with-design-ease/v2"
# Half the EN 13402-3 band of the primary girth (8 cm for most letters): a body anywhere in a size's
# band fits it.
EASE_TOLERANCE_CM = 4.0
CLOSE_CM = 2.0  # a fit or a miss this narrow names the neighbouring size as the runner-up
# The least room a garment leaves over the layers under it: the least wearing ease of a woven bodice at
# the bust, 1.5 in (3.8 cm; Robinson, Costume Text ch. 16, Central Washington University).
OVER_LAYERS_CM = 3.8
DESIGN_SIZE = "M"


def region_marks(model: BodyModel, marks: Landmarks) -> RegionMarks:
    """Where Anny's topology is cut for the regions (``ease.RegionMarks``)."""
    default = model.vertices(np.asarray(DEFAULT_BETA))
    bones = dict(zip(model.bone_names, model.bone_heads, strict=True))
    leg = np.flatnonzero(model.regions == model.region_names.index("upperleg_l"))
    arm = tuple(joint(default, bones[name]) for name in ARM_JOINTS)
    return RegionMarks(marks.torso, marks.crotch, leg, arm)


@lru_cache(maxsize=4)
def load_sizes(path: Path | None = None) -> dict:
    """``sizes.json``: ``{"styles": {style: {"run", "girths", "design_ease"}}, ...}``."""
    return json.loads(Path(path or models_dir() / "garments" / SIZES_NAME).read_text())


@dataclass(frozen=True)
class Recommendation:
    """The rule's answer: the ``size``, whether it ``fits``, the regions short of their minimum in it
    (``short``), the ``runner_up`` (None: none) and why (``roomier`` / ``closer``)."""

    size: str
    fits: bool
    short: tuple[str, ...]
    runner_up: str | None
    runner_up_is: str | None


def margins(
    ease: dict[str, float], design: dict[str, float], over_layers: dict[str, float] | None = None
) -> dict[str, float]:
    """Per region: how far the ease is above its minimum (>= 0 fits): over the body ``ease``, design
    ease - ``EASE_TOLERANCE_CM``; over the layers ``over_layers`` (None: no layers), ``OVER_LAYERS_CM``;
    the lesser of the two."""
    out = {r: e - (design[r] - EASE_TOLERANCE_CM) for r, e in ease.items() if r in design}
    if over_layers is not None:
        out = {r: min(m, over_layers[r] - OVER_LAYERS_CM) if r in over_layers else m for r, m in out.items()}
    return out


def recommend(
    eases: dict[str, dict[str, float]], design: dict[str, float],
    over_layers: dict[str, dict[str, float]] | None = None,
) -> Recommendation:  # fmt: skip
    """The size (module docstring) among ``eases`` (letter -> region -> ease over the body, cm,
    smallest size first) for a style of design ease ``design`` (region -> cm); ``over_layers``: the
    ease over the body and the layers under it, likewise (None: nothing under)."""
    letters = list(eases)
    margin = {s: margins(eases[s], design, None if over_layers is None else over_layers[s]) for s in letters}
    worst = {s: min(margin[s].values(), default=0.0) for s in letters}
    fitting = [s for s in letters if worst[s] >= 0.0]
    size = fitting[0] if fitting else letters[-1]
    k = letters.index(size)
    short = tuple(r for r, m in margin[size].items() if m < 0.0)
    runner, why = None, None
    if fitting and worst[size] < CLOSE_CM and k + 1 < len(letters):
        runner, why = letters[k + 1], "roomier"
    elif k > 0 and worst[letters[k - 1]] > -CLOSE_CM:
        runner, why = letters[k - 1], "closer"
    return Recommendation(size, bool(fitting), short, runner, why)
