"""Pydantic models of the HTTP API (docs/design.md section 6): the only place pydantic meets requests.

Requests are strict (no "180" for 180, no true for 1) and closed (unknown fields are errors), so a
typo in an option is refused instead of silently ignored. Bounds here are the widest the body model
serves (``service.pipeline.body_build``: heights, and BMI at the shortest and tallest of them); the exact
weight range depends on the height and each girth's on gender, height and weight, and are checked
against the body model (a 422 naming the range possible).
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StringConstraints, ValidationInfo, field_validator

from service.pipeline.body_build import BMI_RANGE, HEIGHT_RANGE_CM, weight_range_kg
from service.pipeline.catalog import Category
from service.pipeline.gltf import Compression
from service.pipeline.outfit import MAX_GARMENTS
from service.pipeline.sizes import LETTERS
from service.pipeline.tryon import GARMENT_ID, GIRTH_FIELDS, OutfitSpec

GarmentId = Annotated[str, StringConstraints(pattern=f"^{GARMENT_ID}$")]
Girth = Literal["chest_cm", "waist_cm", "hip_cm"]
# The served heights, and the weights of BMI_RANGE over them rounded outwards to 0.1 kg (23.6-308.7):
# the schema never refuses what the body model accepts.
HEIGHT_CM = HEIGHT_RANGE_CM
WEIGHT_KG = (math.floor(round(weight_range_kg(HEIGHT_CM[0])[0] * 10, 6)) / 10,
             math.ceil(round(weight_range_kg(HEIGHT_CM[1])[1] * 10, 6)) / 10)  # fmt: skip
GIRTH_ALLOWED = ("a number above 0, or null (predicted from height and weight when missing); the exact "
                 "range depends on gender, height and weight (GET /v1/body/ranges)")  # fmt: skip
BODY_QUERY = "`gender`, `height_cm`, `weight_kg`, `chest_cm`, `waist_cm`, `hip_cm`"
# What each request field accepts, quoted in every 4xx about it.
ALLOWED = {
    "": "a JSON object with `garments` (required), `body` and `options`",
    "garments": f"a list of 1-{MAX_GARMENTS} distinct garments, inner to outer, each a garment id or "
    "`{\"id\": ..., \"size\": ...}` (GET /v1/garments lists the ids and each one's sizes)",
    "garments.id": "a garment id (GET /v1/garments)",
    "garments.size": f"one of {', '.join(LETTERS)} where the garment comes in sizes (GET /v1/garments), or "
    "null: the one-size garment cut to the body",
    "body": "an object with `gender`, `height_cm`, `weight_kg` and, each optional, `chest_cm`, `waist_cm`, "
    "`hip_cm`",
    "body.gender": "a number from 0 (male) to 1 (female)",
    "body.height_cm": f"a number from {HEIGHT_CM[0]:g} to {HEIGHT_CM[1]:g}",
    "body.weight_kg": f"a number from {WEIGHT_KG[0]:g} to {WEIGHT_KG[1]:g}; the exact range depends on "
    f"height (BMI {BMI_RANGE[0]:g}-{BMI_RANGE[1]:g})",
    **{f"body.{name}": GIRTH_ALLOWED for name in GIRTH_FIELDS},
    "options": "an object with `untangle`, `include_body`, `measure`, `untangler`, `compression`, `tension`",
    "options.tension": "true or false; true only with `compression` `none`",
    "options.untangle": "true or false",
    "options.include_body": "true or false",
    "options.measure": "true or false",
    "options.untangler": "`neural` or `reference`",
    "query": f"the POST's fields as query parameters (`garments` comma-separated, each `id` or `id:SIZE`, "
    f"{BODY_QUERY}, "
    "`untangle`, `include_body`, `untangler`, `compression`, `tension`), and `v`, `k`, `sig` as made by POST "
    "/v1/outfits",
    "options.compression": "`none` (plain glTF), `quantized` (KHR_mesh_quantization) or `meshopt` "
    "(EXT_meshopt_compression)",
    "query.gender": "a number from 0 (male) to 1 (female)",
    "query.height_cm": f"a number from {HEIGHT_CM[0]:g} to {HEIGHT_CM[1]:g}",
    "query.weight_kg": f"a number from {WEIGHT_KG[0]:g} to {WEIGHT_KG[1]:g}",
}
# What POST /v1/fit accepts where it differs from the outfits' (``ALLOWED``).
FIT_ALLOWED = {
    "": "a JSON object with `style` (required), `under` and `body`",
    "style": "a garment id with sizes (GET /v1/garments)",
    "under": f"a list of 0-{MAX_GARMENTS - 1} distinct garment ids worn under the style, inner first",
}
# What POST /v1/bodies and GET /v1/bodies.glb accept where it differs from the outfits' (``ALLOWED``).
BODY_ALLOWED = {
    "": "a JSON object with `body` and `options`",
    "options": "an object with `compression`",
    "query": f"the POST's fields as query parameters ({BODY_QUERY}, `compression`), and `v`, `k`, `sig` as "
    "made by POST /v1/bodies",
}
CLOSED = ConfigDict(extra="forbid", strict=True)
PREDICTED = ("predicted from height and weight (and the girths given) when missing, from real survey data "
             "(NHANES 2017-2020, ANSUR II); a value outside what adults of that gender, height and weight "
             "have is refused with the range possible (GET /v1/body/ranges).")  # fmt: skip


def distinct_ids(ids: list[str]) -> list[str]:
    """``ids``, or a ValueError naming the ones given more than once."""
    repeated = sorted({g for g in ids if ids.count(g) > 1})
    if repeated:
        raise ValueError(f"repeated id(s) {repeated}")
    return ids


class BodyShape(BaseModel):
    model_config = CLOSED

    gender: float = Field(
        default=0.0, ge=0.0, le=1.0, allow_inf_nan=False, description="0 male .. 1 female (blends between)."
    )
    height_cm: float = Field(
        default=178.0, ge=HEIGHT_CM[0], le=HEIGHT_CM[1], allow_inf_nan=False,
        description="Body height in cm.",
    )  # fmt: skip
    weight_kg: float = Field(
        default=75.0, ge=WEIGHT_KG[0], le=WEIGHT_KG[1], allow_inf_nan=False,
        description=f"Body mass in kg; the supported range depends on height (BMI {BMI_RANGE[0]:g}-"
        f"{BMI_RANGE[1]:g}).",
    )  # fmt: skip
    chest_cm: float | None = Field(
        default=None, gt=0.0, allow_inf_nan=False,
        description="Chest girth (men) or bust girth (women) in cm, ISO 8559-1: the largest horizontal "
        "torso girth between the natural waist and the armpits, measured as a tape would (the convex hull "
        f"of the horizontal section). Optional: {PREDICTED}",
    )  # fmt: skip
    waist_cm: float | None = Field(
        default=None, gt=0.0, allow_inf_nan=False,
        description="Waist girth in cm, ISO 8559-1, at the natural waistline (the smallest torso girth "
        "between the iliac crests and the lowest ribs), measured as a tape would. Optional: "
        f"{PREDICTED}",
    )  # fmt: skip
    hip_cm: float | None = Field(
        default=None, gt=0.0, allow_inf_nan=False,
        description="Hip girth in cm, ISO 8559-1, at the buttocks' most prominent point, measured as a "
        f"tape would. Optional: {PREDICTED}",
    )  # fmt: skip

    def spec(self, garments: tuple[str, ...] = (), **options) -> OutfitSpec:
        """The request's body (and ``garments``, ``options``) as an ``OutfitSpec``."""
        girths = {name: None if getattr(self, name) is None else float(getattr(self, name))
                  for name in GIRTH_FIELDS}  # fmt: skip
        return OutfitSpec(garments, float(self.gender), float(self.height_cm), float(self.weight_kg),
                          **girths, **options)  # fmt: skip


class OutfitOptions(BaseModel):
    model_config = CLOSED

    untangle: bool = Field(default=True, description="Untangle the layers (false: explicit meshes only).")
    include_body: bool = Field(default=True, description="Add the body as node `body` to the GLB.")
    measure: bool = Field(
        default=False, description="Add penetration and intersection measures to the report (slow)."
    )
    untangler: Literal["neural", "reference"] = Field(
        default="neural", description="Untangling operator: the neural one or the exact reference."
    )
    compression: Compression = Field(
        default="none",
        description="GLB encoding: `none` (plain glTF, any viewer), `quantized` (KHR_mesh_quantization: "
        "int16 positions, int8 normals) or `meshopt` (EXT_meshopt_compression on top; the viewer needs "
        "meshopt's decoder). Not part of the outfit id: every encoding is the same outfit.",
    )
    tension: bool = Field(
        default=False,
        description="Colour each garment by how far its fabric is stretched beyond its cut (COLOR_0 under a "
        "white material, textures left out; white at rest or slack, yellow, red at 5 % stretched: "
        "docs/fit.md) and add `tension` to the report. Plain encoding only (`compression` `none`).",
    )

    @field_validator("tension")
    @classmethod
    def _tension_is_plain(cls, tension: bool, info: ValidationInfo) -> bool:
        compression = info.data.get("compression", "none")
        if tension and compression != "none":
            raise ValueError(f"the tension map is in the plain encoding only (compression {compression!r})")
        return tension


class SizedGarment(BaseModel):
    """A garment worn in one of its sizes (docs/fit.md)."""

    model_config = CLOSED

    id: GarmentId = Field(description="Garment id (GET /v1/garments).")
    size: Literal[LETTERS] | None = Field(  # type: ignore[valid-type]
        default=None,
        description="The size worn, one of the garment's `sizes` (GET /v1/garments): its cut is that size's "
        "pattern, tight on a body bigger than its chart and loose on a smaller one. null: the one-size "
        "garment cut to the body, as a bare id.",
    )


def garment_items(items: list) -> tuple[tuple[str, ...], tuple[str | None, ...]]:
    """(ids, sizes) of the request's ``garments`` items: ids and ``SizedGarment``s."""
    ids = tuple(g if isinstance(g, str) else g.id for g in items)
    return ids, tuple(None if isinstance(g, str) else g.size for g in items)


class OutfitRequest(BaseModel):
    model_config = ConfigDict(
        extra="forbid",
        strict=True,
        json_schema_extra={
            "examples": [
                {
                    "garments": ["pants", {"id": "tshirt", "size": "M"}, "jacket"],
                    "body": {"gender": 0.0, "height_cm": 180, "weight_kg": 80},
                    "options": {"untangle": True, "include_body": True},
                }
            ]
        },
    )

    garments: list[GarmentId | SizedGarment] = Field(
        min_length=1,
        max_length=MAX_GARMENTS,
        description="Garments, inner to outer, each at most once: a garment id (the one-size garment cut to "
        "the body) or `{\"id\": ..., \"size\": \"M\"}` (that size's cut). An order no cloth can take "
        "(pants over a skirt) is refused with a 422 on `garments` that names the garments and why "
        "(docs/collisions.md, 'Refused orders'); a size the garment does not come in, with a 422 on "
        "`garments.K.size` naming the sizes it has.",
    )
    body: BodyShape = Field(default_factory=BodyShape)
    options: OutfitOptions = Field(default_factory=OutfitOptions)

    @field_validator("garments")
    @classmethod
    def _distinct(cls, items: list) -> list:
        distinct_ids(list(garment_items(items)[0]))
        return items

    def spec(self) -> OutfitSpec:
        o = self.options
        ids, sizes = garment_items(self.garments)
        return self.body.spec(ids, untangle=o.untangle, include_body=o.include_body, measure=o.measure,
                              untangler=o.untangler, sizes=sizes, tension=o.tension)  # fmt: skip


BODY_EXAMPLE = {"height_cm": 165.0, "weight_kg": 60.0, "chest_cm": 87.9, "waist_cm": 68.7, "hip_cm": 100.0,
                "predicted": ["chest_cm", "waist_cm"]}  # fmt: skip


class BodyReport(BaseModel):
    """The body as built, measured on its mesh (docs/body.md): what the GLB's `body` node carries too."""

    model_config = ConfigDict(json_schema_extra={"example": BODY_EXAMPLE})

    height_cm: float = Field(description="Height in cm (the given one within 0.5 cm).")
    weight_kg: float = Field(description="Mass in kg (the given one within 1 %).")
    chest_cm: float = Field(description="Chest (bust) girth in cm, ISO 8559-1, as a tape measures it.")
    waist_cm: float = Field(description="Natural waist girth in cm, ISO 8559-1, as a tape measures it.")
    hip_cm: float = Field(description="Hip girth in cm, ISO 8559-1, as a tape measures it.")
    predicted: list[Girth] = Field(
        description="The girths not given, predicted from the others; a given girth is reproduced within "
        "1 cm."
    )


class OutfitCreated(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "example": {
                "id": "3f1c0d9e8b7a65544332211000ffeedd",
                "glb_url": "/v1/outfits/3f1c0d9e8b7a65544332211000ffeedd.glb",
                "cached": False,
                "report": {
                    "garments": ["tshirt"],
                    "untangled": True,
                    "collision_free": True,
                    "crossing_pairs": 0,
                    "numerical_fallback": [],
                    "seconds": {"body": 0.0005, "total": 0.15},
                },  # fmt: skip
            }
        }
    )

    id: str = Field(description="Outfit id: a hash of the canonical request and the model version.")
    glb_url: str = Field(description="GET it for the GLB (while the outfit is in the cache).")
    cached: bool = Field(description="Whether the outfit came from the cache.")
    report: dict[str, Any] = Field(
        description="Quality report: garments, beta, untangling statistics, `collision_free` (no "
        "triangle pairs crossing between layers and no vertex left inside an inner layer after the "
        "repair; `crossing_pairs` counts what is left), `numerical_fallback` (garments served unfitted "
        "after a numerical fault), `attempts` (how many times the outfit was made: more than 1 where a "
        "garment let down around an inner one's lower junction came out crossing and was made again "
        "with more room), `seconds` per pipeline stage, `sizes` (each garment's size, null for the "
        "one-size garment), `tension` with `options.tension` (per garment `stretch_p50`, `stretch_p95`, "
        "`stretch_max` and `stretched_share`: its fabric's stretch against its cut, docs/fit.md), and "
        "`body` (a `BodyReport`: the body as built, measured on its mesh, and which girths were "
        "predicted).",
        json_schema_extra={"properties": {"body": {"$ref": "#/components/schemas/BodyReport"}}},
    )


class BodyOptions(BaseModel):
    model_config = CLOSED

    compression: Compression = Field(
        default="none", description="GLB encoding, as `options.compression` of POST /v1/outfits."
    )


class BodyRequest(BaseModel):
    model_config = ConfigDict(
        extra="forbid",
        strict=True,
        json_schema_extra={
            "examples": [{"body": {"gender": 1.0, "height_cm": 165, "weight_kg": 60, "hip_cm": 100}}]
        },
    )

    body: BodyShape = Field(default_factory=BodyShape)
    options: BodyOptions = Field(default_factory=BodyOptions)

    def spec(self) -> OutfitSpec:
        """The body as an ``OutfitSpec`` without garments (``ModelEngine.make_body``)."""
        return self.body.spec()


class BodyCreated(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "example": {
                "body": BODY_EXAMPLE,
                "glb_url": "/v1/bodies.glb?gender=1&height_cm=165&weight_kg=60&hip_cm=100&v=4b5b0419f93c",
            }
        }
    )

    body: BodyReport = Field(description="The body as built, measured on its mesh.")
    glb_url: str = Field(description="GET it for the body's GLB, on any replica (signed with API keys on).")


REGION = Literal["chest", "waist", "waistband", "hip", "thigh", "upper_arm"]
SIZE = Literal["XS", "S", "M", "L", "XL", "XXL"]


class FitRequest(BaseModel):
    model_config = ConfigDict(
        extra="forbid",
        strict=True,
        json_schema_extra={
            "examples": [{"style": "jacket", "under": ["tshirt"],
                          "body": {"gender": 1.0, "height_cm": 165, "weight_kg": 60, "hip_cm": 100}}]
        },
    )  # fmt: skip

    style: GarmentId = Field(description="The garment whose sizes are fitted (a style with sizes).")
    under: list[GarmentId] = Field(
        default_factory=list, max_length=MAX_GARMENTS - 1,
        description="Garments worn under it, inner first: their girths are under the style's (a jacket over "
        "a sweater fits tighter than over a tank top).",
    )  # fmt: skip
    body: BodyShape = Field(default_factory=BodyShape)

    @field_validator("under")
    @classmethod
    def _distinct(cls, ids: list[str]) -> list[str]:
        return distinct_ids(ids)

    def spec(self) -> OutfitSpec:
        """The body and the layers under, as an ``OutfitSpec`` (``ModelEngine.fit``)."""
        return self.body.spec(tuple(self.under))


class FitRegion(BaseModel):
    garment_cm: float = Field(description="The size's girth there: its finished measurement (docs/fit.md).")
    under_cm: float = Field(description="A tape over the body and every layer under the style there.")
    ease_cm: float = Field(description="garment_cm - under_cm; negative: smaller than what it goes round.")
    body_ease_cm: float = Field(description="The ease over the body alone, as a size chart reckons it.")


class FitSize(BaseModel):
    fits: bool = Field(
        description="Every region's ease over the body is at least its design ease less 4 cm, and over the "
        "layers under it at least 3.8 cm (docs/fit.md)."
    )
    regions: dict[REGION, FitRegion] = Field(description="The regions the style goes round on this body.")


class FitRecommendation(BaseModel):
    size: SIZE = Field(description="The smallest size that fits; none fitting, the largest.")
    fits: bool = Field(description="Whether `size` fits (false: no size of the chart does).")
    short: list[REGION] = Field(description="Regions where `size` is short of its minimum ease.")
    runner_up: SIZE | None = Field(description="The neighbouring size, where a fit or miss is within 2 cm.")
    runner_up_is: Literal["roomier", "closer"] | None = Field(description="What the runner-up would be.")


class FitAnswer(BaseModel):
    model_config = ConfigDict(json_schema_extra={"example": {
        "style": "tshirt", "run": "men", "under": [], "rule": "smallest-size-with-design-ease/v2",
        "recommended": {"size": "M", "fits": True, "short": [], "runner_up": None, "runner_up_is": None},
        "design_ease_cm": {"chest": 9.0, "waist": 8.6, "hip": 8.5},
        "sizes": {"M": {"fits": True,
                        "regions": {"chest": {"garment_cm": 106.9, "under_cm": 97.9, "ease_cm": 9.0,
                                              "body_ease_cm": 9.0}}}},
        "body": BODY_EXAMPLE,
    }})  # fmt: skip

    style: str = Field(description="The style fitted.")
    run: Literal["men", "women"] = Field(description="The size chart its sizes are cut on (docs/fit.md).")
    under: list[str] = Field(description="The garments under it, inner first.")
    rule: str = Field(description="The rule that picked `recommended` (docs/fit.md), with its version.")
    recommended: FitRecommendation
    design_ease_cm: dict[REGION, float] = Field(description="The style's intended ease per region (its M).")
    sizes: dict[SIZE, FitSize] = Field(description="Every size's fit on this body, by region.")
    body: BodyReport = Field(description="The body as built, measured on its mesh.")


class FieldError(BaseModel):
    field: str = Field(description="Dotted path of the offending request field (`body.height_cm`).")
    message: str = Field(description="What is wrong with it.")
    allowed: str = Field(description="What the field accepts.")


class ErrorResponse(BaseModel):
    detail: str = Field(description="Human-readable reason.")
    errors: list[FieldError] | None = Field(default=None, description="Per-field problems (4xx on input).")


class GarmentMaterial(BaseModel):
    base_color: list[float] = Field(description="glTF base colour factor RGBA in [0, 1], times the texture.")
    roughness: float = Field(description="glTF roughness factor.")
    textures: dict[str, str] = Field(
        description="Texture file per slot (`base_color`, `normal`); embedded in every outfit GLB."
    )


class GarmentSummary(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "example": {
                "id": "tshirt",
                "name": "T-shirt",
                "category": "top",
                "layer_rank": 1,
                "vertices": 5210,
                "faces": 10128,
                "openings": ["hem", "neck", "sleeve_l", "sleeve_r"],
                "sizes": list(LETTERS),
                "material": {
                    "base_color": [1.0, 1.0, 1.0, 1.0],
                    "roughness": 0.9,
                    "textures": {"base_color": "tshirt.base.png", "normal": "tshirt.normal.png"},
                },
            }
        }
    )

    id: str = Field(description="Garment id, as used in outfit requests.")
    name: str = Field(description="Human-readable name.")
    category: Category = Field(description="`top`, `bottom` or `dress`.")
    layer_rank: int = Field(
        description="How near the body the garment is worn by default, over the whole catalog (every "
        "category): lower is nearer. Garments worn in rising rank are in the usual order; equal ranks "
        "have no usual order between them."
    )
    vertices: int = Field(description="Vertex count of the rest mesh.")
    faces: int = Field(description="Triangle count of the rest mesh.")
    openings: list[str] = Field(description="Names of the garment's openings (boundary loops), sorted.")
    origin: Literal["bundled", "imported"] = Field(
        default="bundled", description="`bundled` with the service, or `imported` by `ulnef garments import`."
    )
    material: GarmentMaterial | None = Field(
        default=None, description="How it looks in the GLB (UVs and textures); null: a flat colour."
    )
    sizes: list[str] = Field(
        default_factory=list,
        description="The sizes it comes in, smallest first (`{\"id\": ..., \"size\": ...}` in an outfit, "
        "`style` in POST /v1/fit); empty: one size, cut to the body.",
    )


class ReloadResult(BaseModel):
    model_version: str = Field(description="Version now served (outfit ids are keyed on it).")
    garments: int = Field(description="Garments now served.")
    added: list[str] = Field(description="Garment ids served now that were not before.")
    removed: list[str] = Field(description="Garment ids no longer served.")
    left_out: list[str] = Field(description="Imported garments whose files differ from their manifest.")


class GarmentList(BaseModel):
    garments: list[GarmentSummary] = Field(description="Every catalog garment, in catalog order.")


class Range(BaseModel):
    min: float = Field(description="Smallest accepted value.")
    max: float = Field(description="Largest accepted value.")


class BodyRanges(BaseModel):
    model_config = ConfigDict(
        json_schema_extra={
            "example": {
                "gender": 1.0,
                "height_cm": {"min": 135.0, "max": 210.0},
                "weight_kg": {"min": 35.4, "max": 190.5},
                "weight_at_height_cm": 165.0,
                "chest_cm": {"min": 71.8, "max": 109.0},
                "waist_cm": {"min": 61.0, "max": 100.1},
                "hip_cm": {"min": 71.9, "max": 125.7},
                "girths_at_weight_kg": 60.0,
            }
        }
    )

    gender: float = Field(description="The gender the ranges are for.")
    height_cm: Range = Field(description="Heights accepted.")
    weight_kg: Range = Field(description="Weights accepted at `weight_at_height_cm`.")
    weight_at_height_cm: float = Field(
        description="The height the weight range is for: the one asked, moved into the height range."
    )
    chest_cm: Range = Field(description="Chest girths accepted at that height and `girths_at_weight_kg`.")
    waist_cm: Range = Field(description="Waist girths accepted at that height and `girths_at_weight_kg`.")
    hip_cm: Range = Field(description="Hip girths accepted at that height and `girths_at_weight_kg`.")
    girths_at_weight_kg: float = Field(
        description="The weight the girth ranges are for: the one asked (the middle of the weight range "
        "when none), moved into the weight range."
    )


class Health(BaseModel):
    status: Literal["ok"] = Field(description="Always `ok`: the process answers.")


class Readiness(BaseModel):
    ready: bool = Field(description="Whether models are loaded and the self-test outfit passed.")
    garments: int | None = Field(default=None, description="Number of catalog garments, when ready.")
    model_version: str | None = Field(default=None, description="Model version (manifest hash), when ready.")
    detail: str | None = Field(default=None, description="Why the service is not ready.")
