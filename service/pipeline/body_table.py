"""A body from height and weight alone, read from a table: the fast path of ``body_build.build_body``
for a request without girths (the fit itself is the reference, ``tests/pipeline/test_body_table.py``).

``models/body/body_table.npz`` (``python -m training.body_table``) holds, for gender 0 and 1 over a
grid of heights and BMIs covering the served range, the shape ``build_body`` fits from height and
weight alone and the girths ``measure`` reads on it. A request's shape is the table's, interpolated
bilinearly in (height, BMI) and linearly in gender; its height and weight phenotypes are then solved
by Newton's method with exact derivatives (``body_fit.evaluate``) so that the body has exactly the
height and weight asked, in ~3 ms instead of a fit's ~100-300 ms. For a gender of the table its girths
are read on its mesh by a tape (``girth.tape_girths``) at the heights ``measure`` picked on the
table's bodies, interpolated the same way, rather than searched for again: within
``GIRTH_AGREEMENT_CM`` of ``measure`` (tested on random requests), ~4 ms. A gender in between is
measured (``measure``, ~25 ms): its landmarks are not the mix of the sexes' (its bust level was ~2 cm
off, its chest 1.3 cm). Either runs beside the outfit (``body_build``).
The table also says which of its bodies cross themselves (``crossings``): only around those does the
service test a body for crossings (~70 ms) and press it (``body_build.pressed_body``), and a pressed
body is measured (its largest chest girth can move to another level).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from service.geometry.girth import tape_girths
from service.pipeline.body import SHAPE_BOUNDS, BodyModel
from service.pipeline.body_fit import evaluate
from service.pipeline.measurements import Landmarks

TABLE_NAME = "body_table.npz"
GIRTH_COLUMNS = ("chest_cm", "waist_cm", "hip_cm", "waist_iliac_cm")
LEVEL_COLUMNS = ("chest", "waist", "hip", "waist_iliac")  # measure's ``levels_m`` keys, same order
# The table's interpolated girths against ``measure`` on the served mesh, at most (cm): what
# ``tests/pipeline/test_body_table.py`` holds on random requests.
GIRTH_AGREEMENT_CM = 0.5
NEWTON_STEPS = 8
HEIGHT_WEIGHT_TOLERANCE = (1e-4, 1e-4)  # cm, kg: far inside the 0.5 cm and 1 % a body must meet
HW_ROWS = [("height_cm", None), ("weight_kg", None)]


@dataclass(frozen=True, eq=False)
class BodyTable:
    """genders (G,), heights_cm (H,), bmis (B,); shapes (G, H, B, S), girths_cm (G, H, B, 4) and the
    heights they were read at, levels_m (G, H, B, 4), NaN where the fit failed; crossings (G, H, B): how
    many triangle pairs each body's parts cross by (``self_contact``; None: unknown, test every body)."""

    genders: np.ndarray
    heights_cm: np.ndarray
    bmis: np.ndarray
    shapes: np.ndarray
    girths_cm: np.ndarray
    levels_m: np.ndarray
    crossings: np.ndarray | None = None

    @classmethod
    def load(cls, path: Path | str) -> BodyTable:
        with np.load(path, allow_pickle=False) as npz:
            if tuple(npz["girth_columns"].tolist()) != GIRTH_COLUMNS:
                raise ValueError(f"{path}: girth columns {npz['girth_columns']} are not {GIRTH_COLUMNS}")
            crossings = npz["crossings"] if "crossings" in npz.files else None
            return cls(npz["genders"], npz["heights_cm"], npz["bmis"], npz["shapes"], npz["girths_cm"],
                       npz["levels_m"], crossings)  # fmt: skip

    def lookup(
        self, gender: float, height_cm: float, weight_kg: float
    ) -> tuple[np.ndarray, np.ndarray, bool] | None:
        """The interpolated shape ``(S,)``, tape levels ``(4,)`` and whether the body may cross itself
        (a body of the cell's corners, of a gender mixed in, does), or None outside the grid or where a
        corner of the cell failed to fit."""
        bmi = weight_kg / (height_cm / 100.0) ** 2
        cell = [_cell(self.genders, gender), _cell(self.heights_cm, height_cm), _cell(self.bmis, bmi)]
        if None in cell:
            return None
        (k, c), (i, a), (j, b) = cell
        w = np.array([[(1 - a) * (1 - b), (1 - a) * b], [a * (1 - b), a * b]])  # (2, 2)
        mix = np.zeros(len(self.genders))  # (G,): linear in gender between the two nearest
        mix[k : k + 2] = (1.0 - c, c)
        shapes = np.einsum("g,hb,ghbs->s", mix, w, self.shapes[:, i : i + 2, j : j + 2])
        levels = np.einsum("g,hb,ghbs->s", mix, w, self.levels_m[:, i : i + 2, j : j + 2])
        if not (np.all(np.isfinite(shapes)) and np.all(np.isfinite(levels))):
            return None
        shapes[0] = gender
        if self.crossings is None:
            may_cross = True
        else:
            corners = self.crossings[mix > 0, i : i + 2, j : j + 2]
            may_cross = bool(np.any(corners > 0))
        return shapes, levels, may_cross


def _cell(grid: np.ndarray, x: float) -> tuple[int, float] | None:
    """(i, t): x = grid[i] + t (grid[i + 1] - grid[i]), t in [0, 1]; None outside the grid."""
    if not grid[0] <= x <= grid[-1]:
        return None
    i = int(np.clip(np.searchsorted(grid, x, side="right") - 1, 0, len(grid) - 2))
    return i, float((x - grid[i]) / (grid[i + 1] - grid[i]))


def with_height_and_weight(
    model: BodyModel, marks: Landmarks, shape: np.ndarray, height_cm: float, weight_kg: float
) -> np.ndarray | None:
    """``shape (S,)`` with its height and weight phenotypes solved for exactly this height and weight
    (Newton's method, exact 2 x 2 Jacobian); None if it does not converge within the bounds."""
    shape = shape.copy()
    target = np.array([height_cm, weight_kg])
    lo, hi = np.array(SHAPE_BOUNDS[1:3]).T
    for _ in range(NEWTON_STEPS):
        values, jac = evaluate(model, marks, shape, HW_ROWS)
        residual = values - target
        if np.all(np.abs(residual) < HEIGHT_WEIGHT_TOLERANCE):
            return shape
        shape[1:3] = np.clip(shape[1:3] - np.linalg.solve(jac[:, 1:3], residual), lo, hi)
    return None


def girths_at(
    model: BodyModel, marks: Landmarks, vertices: np.ndarray, levels_m: np.ndarray
) -> np.ndarray | None:
    """Tape girths (cm, ``GIRTH_COLUMNS``) of the body ``vertices (V, 3)`` at ``levels_m (4,)``, round the
    torso; None where a level has no torso loop."""
    girths, _ = tape_girths(vertices, model.faces, levels_m, vertices[marks.torso, :2].mean(axis=0))
    return 100.0 * girths if np.all(np.isfinite(girths)) else None
