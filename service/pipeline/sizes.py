"""Size charts (issue 56): the body each letter size is cut for, and which letter a body is.

A chart is a *run* of letter sizes, XS to XXL, each the body measurements (cm) it is made for:
height, chest (bust for women), natural waist and hip, as ISO 8559-1 defines them and
``service.pipeline.measurements`` reads them off a mesh. Two runs:

- **Letters** follow EN 13402-3's letter codes, whose primary dimension is the chest girth for men's
  garments and the bust girth for women's (EN 13402-2); each letter is a band of that girth, and the
  chart's body has the band's centre (``BANDS``).
- **The secondary dimensions** (height, waist, hip) are read at that centre off a retailer's published
  body-measurement chart (FWF Clothing Sizes, "Alle Maße sind Körpermaße",
  https://cdn.shopify.com/s/files/1/1668/0297/files/FWF_Clothing_Sizes.pdf: German men's sizes 44-64,
  women's 34-48), interpolated linearly between its rows. Where FWF has no row (men's XS below its
  chest 88, women's XL and XXL above its bust 108) its own step per size is carried on, and the row is
  marked ``extrapolated``. EN 13402-3's own body tables are not public.

A garment style is cut on one run (``Style.run``, ``service.pipeline.catalog``): unisex tops and
bottoms on the men's, as unisex retail does, the tank top and the skirt on the women's. Its sizes
are the run's letters; each size's rest shape is the style's pattern carried onto that size's chart
body (``training.garments.grading``), so its ease is the style's at every size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LETTERS = ("XS", "S", "M", "L", "XL", "XXL")
RUNS = ("men", "women")
# EN 13402-3 letter-code bands of the primary girth (cm): men's chest, women's bust, XS to XXL.
BANDS: dict[str, tuple[tuple[float, float], ...]] = {
    "men": ((78, 86), (86, 94), (94, 102), (102, 110), (110, 118), (118, 129)),
    "women": ((74, 82), (82, 90), (90, 98), (98, 107), (107, 119), (119, 131)),
}
# FWF's body chart (cm): per German size, (chest or bust, natural waist, hip, height).
FWF = {
    "men": (  # sizes 44, 46, ... 64
        (88, 78, 90, 168), (92, 82, 94, 171), (96, 86, 98, 174), (100, 90, 102, 177),
        (104, 94, 106, 180), (108, 98, 110, 182), (112, 104, 116, 184), (116, 110, 120, 186),
        (120, 116, 124, 188), (124, 121, 128, 190), (128, 126, 132, 192),
    ),
    "women": (  # sizes 34, 36, ... 48; heights 164-170 for every size: its middle, 167
        (80, 64, 91, 167), (84, 68, 94, 167), (88, 72, 97, 167), (92, 76, 100, 167),
        (96, 80, 103, 167), (100, 84, 106, 167), (104, 88, 109, 167), (108, 92, 111, 167),
    ),
}  # fmt: skip
GENDER = {"men": 0.0, "women": 1.0}  # Anny's gender of the run's chart bodies (0 male .. 1 female)


@dataclass(frozen=True)
class ChartRow:
    """The body one letter size is cut for (cm); ``extrapolated``: beyond FWF's rows."""

    letter: str
    height_cm: float
    chest_cm: float
    waist_cm: float
    hip_cm: float
    extrapolated: bool

    def girths(self) -> dict[str, float]:
        return {"chest_cm": self.chest_cm, "waist_cm": self.waist_cm, "hip_cm": self.hip_cm}


def _interpolate(rows: np.ndarray, chest: float) -> tuple[np.ndarray, bool]:
    """(waist, hip, height) at ``chest`` on FWF's rows ``(R, 4)``, linear, carried on past either end
    by the end rows' own step."""
    c = rows[:, 0]
    if chest < c[0]:
        lo, hi = rows[0], rows[1]
    elif chest > c[-1]:
        lo, hi = rows[-2], rows[-1]
    else:
        k = int(np.clip(np.searchsorted(c, chest) - 1, 0, len(c) - 2))
        lo, hi = rows[k], rows[k + 1]
    t = (chest - lo[0]) / (hi[0] - lo[0])
    return lo[1:] + t * (hi[1:] - lo[1:]), not (c[0] <= chest <= c[-1])


def chart(run: str) -> tuple[ChartRow, ...]:
    """The run's chart, XS to XXL."""
    if run not in RUNS:
        raise ValueError(f"run must be one of {RUNS}, got {run!r}")
    rows = np.asarray(FWF[run], dtype=float)
    out = []
    for letter, (lo, hi) in zip(LETTERS, BANDS[run], strict=True):
        chest = (lo + hi) / 2
        (waist, hip, height), outside = _interpolate(rows, chest)
        out.append(ChartRow(letter, round(float(height), 1), chest, round(float(waist), 1),
                            round(float(hip), 1), outside))  # fmt: skip
    return tuple(out)


def letter_of(run: str, chest_cm: float) -> str | None:
    """The letter whose EN 13402-3 band holds ``chest_cm`` (the lower bound inclusive); None outside
    the run."""
    for letter, (lo, hi) in zip(LETTERS, BANDS[run], strict=True):
        if lo <= chest_cm < hi:
            return letter
    return None
