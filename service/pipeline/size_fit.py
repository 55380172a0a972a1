"""A style's fit on a shopper, size by size (issue 56): the answer of ``POST /v1/fit``.

For each size of the style (``models/garments/sizes.json``), every region's ease over the shopper's
body, and over it and the layers she wears under the style (``service.pipeline.ease``), and the size
the rule picks
(``service.pipeline.sizing.recommend``). The layers under, and the style itself for where its waistband
sits, are each garment's explicit model on her body, alone (no untangling: the layers' girths, not
their crossings, are what the tape reads). The girths are the tapes' over the body the service builds
for her (``BuiltBody.vertices``); the garments lie on it opened for cloth, as in an outfit.
"""

from __future__ import annotations

import threading

import numpy as np

from service.pipeline.ease import Layer, body_regions, face_parts, girths
from service.pipeline.sizing import RULE, load_sizes, margins, recommend, region_marks


class SizeFitter:
    """Fits on one ``OutfitModels`` (``models``); ``styles``: the entries of ``sizes.json``."""

    def __init__(self, models, styles: dict | None = None):
        self.models = models
        self.styles = load_sizes()["styles"] if styles is None else styles
        self.marks = region_marks(models.body, models.bodies.marks)
        self._parts: dict[str, np.ndarray] = {}
        self._lock = threading.Lock()

    def parts(self, garment_id: str) -> np.ndarray:
        """The body part of each face of a garment (``ease.face_parts``), made once."""
        with self._lock:
            if garment_id not in self._parts:
                g, body, space = self.models.catalog[garment_id], self.models.body, self.models.space
                self._parts[garment_id] = face_parts(space.mean_vertices, body.regions, body.region_names,
                                                     g.vertices, g.faces)  # fmt: skip
            return self._parts[garment_id]

    def worn(self, garment_id: str, beta: np.ndarray, dressed: np.ndarray) -> Layer:
        """A garment's explicit model on the body ``dressed (V, 3)`` of garment code ``beta (3,)``."""
        g = self.models.catalog[garment_id]
        vertices = self.models.space.to_body(self.models.explicit[garment_id].canonical(beta), dressed)
        return Layer(vertices, g.faces, self.parts(garment_id), g.openings.get("waist"))

    def report(self, built, dressed: np.ndarray, style: str, under: tuple[str, ...] = ()) -> dict:
        """The fit (module docstring) of ``style`` over ``under`` (inner first) on the shopper ``built``
        (a ``BuiltBody``) whose garments lie on ``dressed (V, 3)``."""
        entry = self.styles[style]
        body = body_regions(built.vertices, self.models.body.faces, built.measured.levels_m, self.marks)
        beta = built.garment_beta
        own = self.worn(style, beta, dressed)
        layers = tuple(self.worn(g, beta, dressed) for g in under)
        cut = girths(body, own, layers)
        skin = {r: body_cm for r, (_, body_cm, _) in cut.items()}
        tapes = {r: under_cm for r, (_, _, under_cm) in cut.items()}
        design = entry["design_ease"]
        eases, over = ({size: {r: g - t[r] for r, g in girth.items() if r in t}
                        for size, girth in entry["girths"].items()} for t in (skin, tapes))  # fmt: skip
        picked = recommend(eases, design, over if layers else None)
        sizes = {}
        for size, ease in over.items():
            regions = {
                r: {"garment_cm": round(entry["girths"][size][r], 1), "under_cm": round(tapes[r], 1),
                    "ease_cm": round(e, 1), "body_ease_cm": round(eases[size][r], 1)}
                for r, e in ease.items()
            }  # fmt: skip
            margin = margins(eases[size], design, ease if layers else None)
            sizes[size] = {"fits": all(m >= 0.0 for m in margin.values()), "regions": regions}
        return {
            "style": style,
            "run": entry["run"],
            "under": list(under),
            "rule": RULE,
            "recommended": {
                "size": picked.size, "fits": picked.fits, "short": list(picked.short),
                "runner_up": picked.runner_up, "runner_up_is": picked.runner_up_is,
            },  # fmt: skip
            "design_ease_cm": {r: round(v, 1) for r, v in design.items()},
            "sizes": sizes,
        }
