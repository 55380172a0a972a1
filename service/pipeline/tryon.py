"""One try-on request from validated values to GLB bytes, HTTP-free.

``OutfitSpec`` is the canonical form of a request (what the cache and the outfit id are keyed on);
``ModelEngine`` runs it on the loaded models and guarantees a GLB without NaN: a garment whose
fitted mesh is not finite, or whose untangling raised, falls back to its explicit (tangled) mesh
and is named in ``report["numerical_fallback"]``.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal, Protocol

import numpy as np

from service.process.manifest import MANIFEST_NAME

log = logging.getLogger(__name__)
UntanglerKind = Literal["neural", "reference"]
# numpy's errors and what a failed solve raises; anything else is a bug and should surface.
NUMERICAL_ERRORS = (ArithmeticError, np.linalg.LinAlgError, RuntimeError, ValueError)
# Garment ids, one rule for the API (``service.server.schemas``) and the import
# (``training.garment_import``): 32 characters, the API's limit since its first version.
GARMENT_ID_MAX_CHARS = 32
GARMENT_ID = rf"[a-z][a-z0-9_]{{0,{GARMENT_ID_MAX_CHARS - 1}}}"  # a regex, without anchors
GARMENT_ID_RULE = f"1-{GARMENT_ID_MAX_CHARS} lower case letters, digits and _, starting with a letter"


GIRTH_FIELDS = ("chest_cm", "waist_cm", "hip_cm")


class InvalidField(ValueError):
    """A request value the models cannot serve: ``field`` is its dotted path, ``allowed`` says what is."""

    def __init__(self, field: str, message: str, allowed: str):
        super().__init__(message)
        self.field = field
        self.allowed = allowed


@dataclass(frozen=True)
class OutfitSpec:
    """A request in canonical form: garments inner to outer, body in human units, options. ``sizes``:
    the size each garment is worn in, parallel to ``garments`` (None: the one-size garment cut to the
    body, ``service.pipeline.size_model``); empty when none is named."""

    garments: tuple[str, ...]
    gender: float = 0.0
    height_cm: float = 178.0
    weight_kg: float = 75.0
    chest_cm: float | None = None
    waist_cm: float | None = None
    hip_cm: float | None = None
    untangle: bool = True
    include_body: bool = True
    measure: bool = False
    untangler: UntanglerKind = "neural"
    sizes: tuple[str | None, ...] = ()
    tension: bool = False

    def __post_init__(self):
        if not any(self.sizes):  # one form for "no size named": the same outfit, the same id
            object.__setattr__(self, "sizes", ())
        elif len(self.sizes) != len(self.garments):
            raise ValueError(f"sizes: {len(self.sizes)} for {len(self.garments)} garments")

    def size_of(self, k: int) -> str | None:
        """The size garment ``k`` is worn in (None: one size)."""
        return self.sizes[k] if self.sizes else None

    def canonical_json(self) -> str:
        """Stable text of the request: same outfit, same text (floats by ``repr``, keys sorted; ``sizes``
        only where one is named, so that the outfits before sizes keep their ids)."""
        fields = asdict(self) | {k: float(getattr(self, k)) for k in ("gender", "height_cm", "weight_kg")}
        fields |= {k: None if getattr(self, k) is None else float(getattr(self, k)) for k in GIRTH_FIELDS}
        fields["garments"] = list(self.garments)
        if self.sizes:
            fields["sizes"] = list(self.sizes)
        else:
            del fields["sizes"]
        if not self.tension:
            del fields["tension"]
        return json.dumps(fields, sort_keys=True, separators=(",", ":"))

    def outfit_id(self, model_version: str) -> str:
        """32 hex chars naming this outfit on these models (a new model version gives new ids)."""
        text = f"{model_version}\n{self.canonical_json()}"
        return hashlib.sha256(text.encode()).hexdigest()[:32]


@dataclass
class OutfitResult:
    """GLB bytes (glTF 2.0, Y up, plain), the JSON-able quality report, and the layers the GLB was
    written from (``GltfLayer``s or their tuples), kept so that a compact encoding asked for later
    (``encoded``) needs no second outfit computation."""

    glb: bytes
    report: dict = field(default_factory=dict)
    layers: list | None = None
    _encoded: dict[str, bytes] = field(default_factory=dict, repr=False)

    def encoded(self, compression: str) -> bytes:
        """The GLB in ``compression`` (``service.pipeline.gltf.outfit_glb``), written on first use."""
        if compression == "none":
            return self.glb
        data = self._encoded.get(compression)
        if data is None:
            if self.layers is None:
                raise ValueError(f"no layers kept: cannot encode {compression!r}")
            from service.pipeline.gltf import outfit_glb

            data = self._encoded.setdefault(compression, outfit_glb(self.layers, compression))
        return data

    def has(self, compression: str) -> bool:
        return compression == "none" or compression in self._encoded

    @property
    def nbytes(self) -> int:
        """Bytes held: every encoding written so far and the layers' vertices (faces are the
        catalog's, shared by every outfit)."""
        kept = sum(np.asarray(layer[1] if isinstance(layer, tuple) else layer.vertices).nbytes
                   for layer in self.layers or ())  # fmt: skip
        return len(self.glb) + sum(len(d) for d in self._encoded.values()) + kept


class Engine(Protocol):
    """What the HTTP layer needs from the pipeline (a fake one in the HTTP tests)."""

    model_version: str

    def garment_ids(self) -> list[str]: ...

    def validate(self, spec: OutfitSpec) -> None:
        """Raise ``InvalidField`` for what only the models know is wrong (ids, body range)."""

    def make(self, spec: OutfitSpec) -> OutfitResult: ...

    def make_body(self, spec: OutfitSpec) -> OutfitResult:
        """The body of ``spec`` alone (its garments are ignored): GLB and ``report["body"]``."""

    def fit(self, spec: OutfitSpec, style: str) -> dict:
        """``style``'s fit, size by size, on the body of ``spec`` over ``spec.garments`` worn under it
        (``service.pipeline.size_fit``): the answer of ``POST /v1/fit``, ``report["body"]`` included."""

    def body_ranges(self, gender: float, height_cm: float | None, weight_kg: float | None = None) -> dict:
        """``{"height_cm": (lo, hi), "weight_kg": (lo, hi), "at_height_cm": h, "at_weight_kg": w,
        "chest_cm": ..., "waist_cm": ..., "hip_cm": ...}``: what ``validate`` accepts for this gender,
        the weights at ``height_cm`` (clamped into the height range; its middle when None) and the
        girths at ``weight_kg`` (likewise). Bounds as refusals print them
        (``service.pipeline.body.printed_bounds``)."""


def check_garment_ids(
    garments: tuple[str, ...], allowed: list[str], max_garments: int, field: str = "garments"
) -> None:
    """Raise ``InvalidField(field, ...)`` unless 1..max_garments distinct ids from ``allowed``."""
    listing = f"1-{max_garments} distinct ids, inner to outer, from: {', '.join(allowed)}"
    if not 1 <= len(garments) <= max_garments:
        raise InvalidField(field, f"{len(garments)} given", listing)
    unknown = [g for g in garments if g not in allowed]
    if unknown:
        raise InvalidField(field, f"unknown id(s) {unknown}", listing)
    repeated = sorted({g for g in garments if garments.count(g) > 1})
    if repeated:
        raise InvalidField(field, f"repeated id(s) {repeated}", listing)


def check_sizes(spec: OutfitSpec, sized: dict, field: str = "garments") -> None:
    """Raise ``InvalidField(f"{field}.k.size", ...)`` for a size garment k does not come in; ``sized``:
    garment id -> its ``SizeModel`` (the garments with sizes)."""
    for k, gid in enumerate(spec.garments):
        if (size := spec.size_of(k)) is None:
            continue
        model = sized.get(gid)
        if model is None:
            with_sizes = ", ".join(sorted(sized)) or "none"
            raise InvalidField(f"{field}.{k}.size", f"{gid!r} comes in one size",
                               f"no size for {gid!r} (garments with sizes: {with_sizes})")  # fmt: skip
        if size not in model.letters:
            allowed = f"one of {', '.join(model.letters)}, or none (one size cut to the body)"
            raise InvalidField(f"{field}.{k}.size", f"{gid!r} has no size {size!r}", allowed)


UNDER_RULE = "garment ids worn under the style, inner first, other than the style (GET /v1/garments)"


class RefusedOrder(InvalidField):
    """A garment order no cloth can take (``service.pipeline.collisions.layering``): a 422 on ``garments``."""


ORDER_RULE = (
    "an order cloth can take (docs/collisions.md, 'Refused orders'): swap the garments named, or drop one"
)


def check_order(refusals: list, field: str = "garments") -> None:
    """Raise ``InvalidField(field, ...)`` naming each refused pair and why
    (``service.pipeline.collisions.layering``)."""
    if refusals:
        reasons = "; ".join(r.reason for r in refusals)
        raise RefusedOrder(field, f"order refused: {reasons}", ORDER_RULE)


def model_version(models_dir: Path) -> str:
    """First 12 hex chars of the manifest's sha256 (it lists every model file's sha256)."""
    path = Path(models_dir) / MANIFEST_NAME
    if not path.is_file():
        return "unversioned"
    return hashlib.sha256(path.read_bytes()).hexdigest()[:12]


def glb_layers(
    garments, catalog: dict, body: tuple[np.ndarray, np.ndarray] | None, extras: dict | None = None,
    sizes: dict[str, str | None] | None = None,
):  # fmt: skip
    """``GltfLayer``s of fitted ``garments`` [(id, vertices (V, 3), faces (F, 3))], each with its catalog
    look (display mesh and material, when it has one) and, worn in a size (``sizes``), ``{"size"}`` as
    its node's extras; the body's (vertices, faces) first unless None, with ``extras`` on its node."""
    from service.pipeline.gltf import GltfLayer

    layers = [GltfLayer("body", *body, extras=extras)] if body is not None else []
    for gid, v, f in garments:
        g, size = catalog.get(gid), (sizes or {}).get(gid)
        look = (g.display, g.material) if g else (None, None)
        layers.append(GltfLayer(gid, v, f, *look, extras=None if size is None else {"size": size}))
    return layers


def finite_layers(
    garments: list[tuple[str, np.ndarray, np.ndarray]],
    fallback: dict[str, np.ndarray],
) -> tuple[list[tuple[str, np.ndarray, np.ndarray]], list[str]]:
    """Replace non-finite garment vertices (V, 3) by ``fallback[id]`` (V, 3); returns layers and the
    ids replaced. Garments still not finite are dropped and listed too, so no NaN reaches a GLB."""
    out, flagged = [], []
    for gid, v, f in garments:
        if np.all(np.isfinite(v)):
            out.append((gid, v, f))
            continue
        flagged.append(gid)
        alt = fallback.get(gid)
        if alt is not None and np.all(np.isfinite(alt)):
            out.append((gid, alt, f))
    return out, flagged


def worn_deltas(spec: OutfitSpec, sized: dict, measured) -> dict[str, np.ndarray]:
    """Each sized garment's delta ``(2,)`` on the body ``measured`` (``BodyMeasurements``)."""
    out = {}
    for k, gid in enumerate(spec.garments):
        if (size := spec.size_of(k)) is not None:
            model = sized[gid]
            wearer = np.array([getattr(measured, f"{model.primary}_cm"), measured.height_cm])
            out[gid] = model.delta(size, wearer)
    return out


def _refused_as_invalid(build):
    """``build()``, a body refusal (``ShapeOutOfRange``) raised as ``InvalidField`` (a 422)."""
    from service.pipeline.body import ShapeOutOfRange, format_range

    try:
        return build()
    except ShapeOutOfRange as e:
        allowed = "a finite number" if e.allowed is None else format_range(*e.allowed)
        raise InvalidField(f"body.{e.field}", str(e), allowed) from None


def _body_request(spec: OutfitSpec):
    from service.pipeline.body_build import BodyRequest

    girths = {k: getattr(spec, k) for k in GIRTH_FIELDS}
    return BodyRequest(spec.gender, spec.height_cm, spec.weight_kg, **girths)


class ModelEngine:
    """``Engine`` over ``service.pipeline.outfit.OutfitModels`` (thread-safe: onnxruntime sessions are)."""

    def __init__(self, models, version: str):
        from functools import lru_cache

        from service.pipeline.body_build import BODY_CACHE

        self.models = models
        self.model_version = version
        self._dressed = lru_cache(maxsize=BODY_CACHE)(self._dressed_vertices)
        self._fitter = None
        self._cuts = None  # the tension map's rest shapes (service.pipeline.tension.CutShapes), made on use

    @classmethod
    def load(cls, models_dir: Path, threads: int, imported: list[Path] = ()) -> ModelEngine:
        """The engine over ``models_dir`` and the ``imported`` garment directories; the version
        covers both (an import changes outfit ids)."""
        from service.pipeline.outfit import OutfitModels

        version = model_version(models_dir)
        if imported:
            manifests = "".join(model_version(d) for d in imported)
            version = hashlib.sha256((version + manifests).encode()).hexdigest()[:12]
        models = OutfitModels.load(models_dir, threads=threads, imported=imported)
        models.warm()  # ~1 s here rather than on first requests (layering and drape profiles)
        return cls(models, version)

    def garment_ids(self) -> list[str]:
        return list(self.models.catalog)

    def validate(self, spec: OutfitSpec) -> None:
        from service.pipeline.outfit import MAX_GARMENTS

        check_garment_ids(spec.garments, self.garment_ids(), MAX_GARMENTS)
        check_order(self.models.refusals(list(spec.garments)))
        check_sizes(spec, self.models.sizes)
        self.body(spec)

    def body(self, spec: OutfitSpec):
        """The shopper's ``BuiltBody`` (``service.pipeline.body_build``), kept per process."""
        return self._built(_body_request(spec))

    def dressed(self, spec: OutfitSpec) -> np.ndarray:
        """``(V, 3)``: the shopper's body with room for cloth where its parts touch
        (``service.pipeline.dressed_body``), kept per process."""
        return self._dressed(_body_request(spec))

    def _dressed_vertices(self, request) -> np.ndarray:
        from service.pipeline.dressed_body import dressed_vertices

        return dressed_vertices(self.models.body, self._built(request))

    def _built(self, request):
        return _refused_as_invalid(lambda: self.models.bodies.build(request))

    def body_report(self, built) -> dict:
        """``built.report()``, waiting for its measurement; a body that cannot be measured is a 422."""
        return _refused_as_invalid(built.report)

    def body_ranges(self, gender: float, height_cm: float | None, weight_kg: float | None = None) -> dict:
        return self.models.bodies.ranges(gender, height_cm, weight_kg)

    def make_body(self, spec: OutfitSpec) -> OutfitResult:
        from service.pipeline.gltf import GltfLayer, outfit_glb

        built = self.body(spec)
        vertices = built.vertices
        report = self.body_report(built)
        layers = [GltfLayer("body", vertices, self.models.body.faces, extras={"body": report})]
        return OutfitResult(outfit_glb(layers), {"body": report}, layers)

    def fit(self, spec: OutfitSpec, style: str) -> dict:
        from service.pipeline.outfit import MAX_GARMENTS
        from service.pipeline.size_fit import SizeFitter

        if self._fitter is None:
            self._fitter = SizeFitter(self.models)
        styles = sorted(self._fitter.styles)
        if style not in styles:
            known = "known" if style in self.models.catalog else "unknown"
            message = f"{known} garment {style!r} has no sizes"
            raise InvalidField("style", message, f"one of {', '.join(styles)}")
        under = spec.garments
        if under:
            check_garment_ids(under, self.garment_ids(), MAX_GARMENTS - 1, "under")
            if style in under:
                raise InvalidField("under", f"{style!r} is the style fitted", UNDER_RULE)
            check_order(self.models.refusals([*under, style]), "under")
        built = self.body(spec)
        report = self._fitter.report(built, self.dressed(spec), style, under)
        return report | {"body": self.body_report(built)}

    def make(self, spec: OutfitSpec) -> OutfitResult:
        from service.pipeline.gltf import outfit_glb
        from service.pipeline.outfit import make_outfit

        started = time.perf_counter()  # the passes' deadline counts the body's build (pass_seconds)
        built = self.body(spec)
        beta, body_vertices = built.garment_beta, self.dressed(spec)
        ids = list(spec.garments)
        deltas = worn_deltas(spec, self.models.sizes, built.measured)

        def explicit_outfit():
            return make_outfit(self.models, ids, beta, untangle_layers=False, measure=False,
                               body_vertices=body_vertices, deltas=deltas)

        flagged: list[str] = []
        try:
            outfit = make_outfit(self.models, ids, beta, spec.untangle, spec.untangler, measure=spec.measure,
                                 body_vertices=body_vertices, started=started, deltas=deltas)
        except NUMERICAL_ERRORS as e:
            if not spec.untangle:
                raise
            log.warning("untangling failed, serving explicit meshes: %r", e)
            outfit, flagged = explicit_outfit(), list(ids)
        garments = outfit.garments
        if not all(np.all(np.isfinite(v)) for _, v, _ in garments):
            explicit = {g: v for g, v, _ in explicit_outfit().garments}
            garments, bad = finite_layers(garments, explicit)
            flagged += bad
        body = (outfit.body_vertices, outfit.body_faces) if spec.include_body else None
        body_report = self.body_report(built)
        worn = {g: spec.size_of(k) for k, g in enumerate(spec.garments)}
        layers = glb_layers(garments, self.models.catalog, body, {"body": body_report}, worn)
        report = dict(outfit.report) | {"body": body_report}
        if spec.tension:
            report["tension"] = self._tension(layers, worn, built.vertices)
        report["numerical_fallback"] = flagged
        report["garments_served"] = [g for g, _, _ in garments]
        report["sizes"] = worn
        return OutfitResult(outfit_glb(layers), report, layers)


    def _tension(self, layers: list, worn: dict, wearer: np.ndarray) -> dict:
        """Colour each garment layer of ``layers`` by its strain (``service.pipeline.tension``), in place;
        returns the report's ``tension``."""
        from dataclasses import replace

        from service.pipeline.tension import CutShapes, strain_summary, tension_colors

        if self._cuts is None:
            self._cuts = CutShapes(self.models)
        out = {}
        for k, layer in enumerate(layers):
            if layer.name not in worn:
                continue
            stretch = self._cuts.stretch(layer.name, worn[layer.name], wearer, layer.vertices)
            layers[k] = replace(layer, colors=tension_colors(stretch))
            out[layer.name] = strain_summary(stretch)
        return out


def self_test(engine: Engine, garments: list[str], untangle: bool) -> OutfitResult:
    """Make one outfit and check it end to end; raises RuntimeError naming what failed."""
    spec = OutfitSpec(garments=tuple(garments), untangle=untangle)
    result = engine.make(spec)
    if result.glb[:4] != b"glTF":
        raise RuntimeError("self-test outfit: not a GLB")
    if result.report.get("numerical_fallback"):
        raise RuntimeError(f"self-test outfit fell back on {result.report['numerical_fallback']}")
    if result.report.get("garments_served", list(garments)) != list(garments):
        raise RuntimeError(f"self-test outfit lost garments: {result.report.get('garments_served')}")
    return result
