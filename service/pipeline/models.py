"""The models a request needs, loaded once: ``LoadedModels`` (immutable) and ``OutfitModels`` over it.

``OutfitModels`` is what a server keeps: the loaded models, the body-clearance helpers
(``collisions.clearance.BodyClearance``) and the per-garment and per-pair caches of collision handling
(``collisions.caches.PairCaches``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from service.geometry.sdf_grid import SdfGrid
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.body_build import BodyBuilder
from service.pipeline.body_table import TABLE_NAME, BodyTable
from service.pipeline.canonical import CanonicalSpace
from service.pipeline.catalog import Garment, load_catalog
from service.pipeline.collisions.caches import PairCaches
from service.pipeline.collisions.clearance import BodyClearance
from service.pipeline.collisions.layering import Refusal
from service.pipeline.explicit import ExplicitModel, ExplicitOnnx
from service.pipeline.fields import FieldSet
from service.pipeline.girth_priors import GirthPriors
from service.pipeline.size_model import SizeModel
from service.pipeline.untangle import untangle_with_jacobian
from service.pipeline.untangle_onnx import NeuralUntangler

UntanglerKind = Literal["neural", "reference"]


@dataclass(frozen=True)
class LoadedModels:
    """Every model file of a models directory (and the imported garments), loaded."""

    body: BodyModel
    catalog: dict[str, Garment]
    explicit: dict[str, ExplicitModel | ExplicitOnnx]
    fields: FieldSet
    neural_untangler: NeuralUntangler
    space: CanonicalSpace
    body_sdf: SdfGrid | None = None
    priors: GirthPriors | None = None  # None: the bundled models' (``GirthPriors.load()``)
    body_table: BodyTable | None = None  # None: every body fitted (``body_build``)
    sizes: dict[str, SizeModel] = field(default_factory=dict)  # the garments worn in sizes (issue 56)

    @classmethod
    def load(cls, directory: Path | None = None, threads: int = 2, imported: list[Path] = ()) -> LoadedModels:
        """The models of ``directory`` (default ``models_dir()``) plus the garments of each
        ``imported`` directory (``garments/``, ``explicit/``, ``fields/``: an imported garment's,
        ``service.pipeline.catalog.imported_garment_dirs``)."""
        from service.process.paths import models_dir
        from service.process.tuning import tune_process

        tune_process()
        directory = Path(directory or models_dir())
        body = BodyModel.load(directory / "body" / "anny_shape.npz")
        catalog = dict(load_catalog(directory / "garments"))
        explicit = {gid: ExplicitOnnx(gid, directory / "explicit") for gid in catalog}
        fields = FieldSet(directory / "fields", threads)
        for extra in imported:
            garments = load_catalog(Path(extra) / "garments", origin="imported")
            taken = sorted(set(garments) & set(catalog))
            if taken:
                raise ValueError(f"{extra}: garment ids {taken} are already in the catalog")
            catalog |= garments
            explicit |= {gid: ExplicitOnnx(gid, Path(extra) / "explicit") for gid in garments}
            fields.add(Path(extra) / "fields")
        return cls(
            body, catalog, explicit, fields,
            NeuralUntangler(directory / "untangler", threads),
            CanonicalSpace.build(body.vertices(np.asarray(DEFAULT_BETA)), body.faces, threads),
            SdfGrid.load(sdf) if (sdf := directory / "body" / "mean_sdf.npz").exists() else None,
            GirthPriors.load(p) if (p := directory / "body" / "girth_priors.json").exists() else None,
            BodyTable.load(t) if (t := directory / "body" / TABLE_NAME).exists() else None,
            {gid: m for gid in catalog if (m := SizeModel.load(gid, directory / "explicit")) is not None},
        )  # fmt: skip


class OutfitModels:
    """Everything a request needs: the loaded models (``loaded``), the body-clearance helpers
    (``clearance``), the collision caches (``pairs``) and the shoppers' bodies (``bodies``), made once
    per process."""

    def __init__(self, loaded: LoadedModels):
        self.loaded = loaded
        self.clearance = BodyClearance(loaded.space.closest, loaded.body_sdf)
        self.pairs = PairCaches(loaded.catalog, loaded.explicit, loaded.space, self.clearance)
        self.bodies = BodyBuilder(loaded.body, loaded.priors or GirthPriors.load(), loaded.body_table)

    @classmethod
    def load(cls, directory: Path | None = None, threads: int = 2, imported: list[Path] = ()) -> OutfitModels:
        """``LoadedModels.load``'s models, with empty caches."""
        return cls(LoadedModels.load(directory, threads, imported))

    @property
    def body(self) -> BodyModel:
        return self.loaded.body

    @property
    def catalog(self) -> dict[str, Garment]:
        return self.loaded.catalog

    @property
    def explicit(self) -> dict[str, ExplicitModel | ExplicitOnnx]:
        return self.loaded.explicit

    @property
    def sizes(self) -> dict[str, SizeModel]:
        return self.loaded.sizes

    @property
    def fields(self) -> FieldSet:
        return self.loaded.fields

    @property
    def space(self) -> CanonicalSpace:
        return self.loaded.space

    def warm(self) -> None:
        """Make the collision caches of the bundled catalog up front (``PairCaches.warm``)."""
        self.pairs.warm()

    def refusals(self, garment_ids: list[str]) -> list[Refusal]:
        """Why cloth cannot take the order ``garment_ids`` (inner to outer): empty when it can."""
        return self.pairs.refusals(garment_ids)

    def untangler(self, kind: UntanglerKind):
        """The operator as ``service.pipeline.fit.Untangler``: (f, Jacobian (P, N, 2N), only its row k
        (P, 1, 2N) when called with ``row=k``, or None)."""
        from service.pipeline.fit import rows_of

        if kind == "neural":
            untangler = self.loaded.neural_untangler

            def neural(f_star, h_star, jacobian, row=None):
                out = untangler.screened(f_star, h_star, jacobian=jacobian, row=row)
                return out.f, out.jacobian

            neural.h_band = untangler.h_band  # it sees h* only through clamp(h* / h_band)
            return neural

        return rows_of(untangle_with_jacobian)
