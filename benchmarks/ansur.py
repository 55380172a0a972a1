"""ANSUR II (US Army, 2012): the chest girths NHANES does not measure.

Data: ``benchmarks/data/ansur/`` (public domain, source and definitions in its README.md), one CSV per
sex. ``load`` returns a ``population.Population`` whose columns carry NHANES's names where the two
surveys measure the same thing (``BMXWT``, ``BMXHT``, ``BMXHIP`` for the buttock circumference, taken
like NHANES's hip at the buttocks' greatest protrusion) and ANSUR's own names for the rest. The
fitting / held-out split is ``population.held_out`` with ``survey="ansur"``.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from benchmarks.population import Population, split

DATA_DIR = Path(__file__).resolve().parent / "data" / "ansur"
FILES = {"female": "ansur2_female.csv", "male": "ansur2_male.csv"}
RENAMED = {"weight_kg": "BMXWT", "stature_cm": "BMXHT", "buttock_cm": "BMXHIP"}
SURVEY = "ansur"


def load(sex: str, data_dir: Path = DATA_DIR) -> Population:
    """Every soldier of ``sex`` (``female`` or ``male``) in file order."""
    with open(data_dir / FILES[sex], newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        values = np.array([[float(x) for x in row] for row in reader if row], dtype=np.float64)
    columns = {RENAMED.get(name, name): values[:, i] for i, name in enumerate(header)}
    return Population(sex, np.arange(len(values)), columns)


def load_split(sex: str) -> tuple[Population, Population]:
    """(fitting set, held-out set) of ``sex``."""
    return split(load(sex), SURVEY)
