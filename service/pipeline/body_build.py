"""A shopper's body from what she knows of it: gender, height, weight and any of chest, waist and hip
girths (issue 55; definitions in ``service.pipeline.measurements``, docs/body.md).

Given measurements are reproduced on the mesh within ``body_fit.TOLERANCE``; missing girths are the
population's typical value given the others (``girth_priors``), fitted as soft targets (one residual
unit = the prediction's standard deviation): the hip and chest, and the NHANES waist at the iliac
crest unless a (natural) waist is given. No survey measures the natural waist, so a missing one is
whatever the body fitted to the rest has. Refusals (``ShapeOutOfRange``, a 422 naming the field and
the range possible): a height or BMI outside ``HEIGHT_RANGE_CM`` / ``BMI_RANGE``, a girth outside
what adults of that height and weight have (``GirthPriors.possible_range``), or a combination the
body cannot take within the tolerances.

Where Anny grows a heavy body's parts through each other (the inner thighs of women from BMI ~32-38,
breasts and belly folds, men's chests from BMI ~43-47: ``models/body/body_table.npz``'s ``crossings``),
the mesh served is pressed into contact (``pressed_body``, ``service.geometry.self_contact``): one
closed surface that does not cross itself, for the fields, the garments and the tape. The weight is
solved again on the pressed mesh, and every measurement reported is read on it.

The garment models were trained on drapes of real adults, tails included (``training.drape``); a
garment takes the code of the default-phenotype body of the shopper's gender, height and weight, its
weight phenotype extrapolated past Anny's box where she is heavier or lighter than it reaches
(``garment_code``), and follows the shopper's own body through the canonical displacement
(``canonical.py``), as on any body.
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from service.geometry.self_contact import Pressed, press_contacts, self_crossings
from service.pipeline.body import (
    SHAPE_BOUNDS,
    BodyModel,
    ShapeOutOfRange,
    body_measurements,
    format_range,
    printed_bounds,
    shape_from_measurements,
    supported_height_range_cm,
    supported_weight_range_kg,
)
from service.pipeline.body_fit import GIVEN_SCALE, TOLERANCE, BodyFit, Target, evaluate, fit_shape
from service.pipeline.body_table import (
    HW_ROWS,
    LEVEL_COLUMNS,
    NEWTON_STEPS,
    BodyTable,
    girths_at,
    with_height_and_weight,
)
from service.pipeline.girth_priors import GirthPriors
from service.pipeline.measurements import BodyMeasurements, Landmarks, landmarks, measure

GIRTHS = ("chest_cm", "waist_cm", "hip_cm")
# Served heights and BMIs: NHANES 2017-2020 adults span 139-200 cm and BMI 14.2-67.0; issue 55 asks
# for 140-205 cm; a little room on each side.
HEIGHT_RANGE_CM = (135.0, 210.0)
BMI_RANGE = (13.0, 70.0)
# Residual evaluations a body's two fits may spend together: a bound on the time an impossible
# combination takes to refuse (~2 s on 2 busy cores; a body NHANES has takes ~20-60).
BODY_EVALUATIONS = 150
# Measurements of table bodies run here, beside the request (``_from_table``): numpy and the tape's
# kernels release the GIL.
_MEASURE_POOL = ThreadPoolExecutor(max_workers=2, thread_name_prefix="body-measure")
# Bodies kept per process: a shopper tries many outfits on one body (~0.1-1 s each to build, ~0.5 MB).
BODY_CACHE = 256
# Where a heavy body's parts cross (thighs, breasts, belly folds) they are pressed into contact this far
# apart (m): the tape and the fields see one surface; the garments' own gap to the skin is 4 mm.
CONTACT_GAP_M = 0.001
# The pressed body loses the overlap its volume counted twice (1-3 % on the heaviest women), so its
# weight is solved again, aiming that much higher, at most this many times; the pressed mesh must then
# weigh within ``PRESSED_WEIGHT_SHARE`` of the request (a third of body_fit.TOLERANCE's 1 %).
PRESS_SOLVES = 3
PRESSED_WEIGHT_SHARE = 0.003
# A rough start for the fit (Anny's height axis: 108.9 cm per unit, women 176.9 cm and men 190.9 cm at
# 0.5; its weight axis, muscle 0.25: ~26 (women) and ~30 (men) BMI per unit above 0.5 at BMI 22 / 24).
START = {"female": (176.9, 22.0, 26.0), "male": (190.9, 24.0, 30.0)}
HEIGHT_CM_PER_UNIT = 108.9


@dataclass(frozen=True)
class BodyRequest:
    """What a shopper gives: gender (0 male .. 1 female), cm, kg; None for a girth not given."""

    gender: float
    height_cm: float
    weight_kg: float
    chest_cm: float | None = None
    waist_cm: float | None = None
    hip_cm: float | None = None

    @property
    def given(self) -> dict[str, float]:
        return {g: float(getattr(self, g)) for g in GIRTHS if getattr(self, g) is not None}


@dataclass(frozen=True)
class BuiltBody:
    """A shopper's body: its extended ``shape (S,)``, its mesh ``vertices (V, 3)`` (the shape's, pressed
    where its parts cross: ``pressed_body``), the ``garment_beta (3,)`` garments take
    (``garment_code``), what the mesh measures, and the value each predicted girth was fitted to
    (name -> cm)."""

    shape: np.ndarray
    vertices: np.ndarray = field(repr=False)
    garment_beta: np.ndarray
    measurement: BodyMeasurements | Future  # a Future: being measured (``measured`` waits for it)
    predicted: dict[str, float]
    given: tuple[str, ...]
    fit: BodyFit | None = field(repr=False)  # None: read from the table (``body_table``)
    pressed: Pressed | None = field(default=None, repr=False)  # None: nothing crossed

    @property
    def measured(self) -> BodyMeasurements:
        """What the mesh measures (waits for a measurement still running: ``_from_table``)."""
        m = self.measurement
        if not isinstance(m, Future):
            return m
        try:
            return m.result()
        except ValueError as e:  # the table's bodies all measure; kept from turning into a 500
            raise ShapeOutOfRange("weight_kg", f"this body could not be measured: {e}") from None

    def report(self) -> dict:
        """The body as built, for the JSON report and the GLB (rounded to 0.1 cm / 0.1 kg)."""
        m = self.measured
        return {
            "height_cm": round(m.height_cm, 1),
            "weight_kg": round(m.weight_kg, 1),
            "chest_cm": round(m.chest_cm, 1),
            "waist_cm": round(m.waist_cm, 1),
            "hip_cm": round(m.hip_cm, 1),
            "predicted": sorted(g for g in GIRTHS if g not in self.given),
        }


def _number(name: str, value) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ShapeOutOfRange(name, f"{name}={value!r} is not a number") from None
    if not np.isfinite(x):
        raise ShapeOutOfRange(name, f"{name}={x} is not a finite number")
    return x


def check_request(priors: GirthPriors, request: BodyRequest) -> BodyRequest:
    """The request with its numbers checked, in order (gender, height, weight, then each girth given
    the others); raises ``ShapeOutOfRange`` naming the first field out of range and what is allowed."""
    g = _number("gender", request.gender)
    if not 0.0 <= g <= 1.0:
        raise ShapeOutOfRange(
            "gender", f"gender={g:g} is outside the supported range 0-1 (0 male, 1 female)", (0.0, 1.0)
        )
    h = _number("height_cm", request.height_cm)
    if not HEIGHT_RANGE_CM[0] <= h <= HEIGHT_RANGE_CM[1]:
        raise ShapeOutOfRange(
            "height_cm",
            f"height_cm={h:g} is outside the supported range {format_range(*HEIGHT_RANGE_CM)} cm",
            HEIGHT_RANGE_CM,
        )
    w = _number("weight_kg", request.weight_kg)
    w_range = weight_range_kg(h)
    if not w_range[0] <= w <= w_range[1]:
        raise ShapeOutOfRange(
            "weight_kg",
            f"weight_kg={w:g} is outside the supported range "
            f"{format_range(*w_range)} kg for height_cm={h:g} (BMI {BMI_RANGE[0]:g}-"
            f"{BMI_RANGE[1]:g})",
            w_range,
        )
    girths = {}
    for name in GIRTHS:
        value = getattr(request, name)
        if value is None:
            continue
        x = _number(name, value)
        lo, hi = priors.possible_range(g, name, h, w)
        if not lo <= x <= hi:
            raise ShapeOutOfRange(
                name,
                f"{name}={x:g} is outside the range {format_range(lo, hi)} cm that adults "
                f"of height_cm={h:g} and weight_kg={w:g} have",
                (lo, hi),
            )
        girths[name] = x
    return BodyRequest(g, h, w, **girths)


def weight_range_kg(height_cm: float) -> tuple[float, float]:
    """Weights (kg) served at this height: ``BMI_RANGE`` times the height squared."""
    return tuple(b * (height_cm / 100.0) ** 2 for b in BMI_RANGE)


def targets_of(priors: GirthPriors, request: BodyRequest) -> tuple[dict[str, Target], dict[str, float]]:
    """The fit's targets (given ones tight, predicted ones soft) and the predicted values (cm)."""
    given = request.given
    targets = {
        "height_cm": Target(request.height_cm, GIVEN_SCALE * TOLERANCE["height_cm"]),
        "weight_kg": Target(request.weight_kg, GIVEN_SCALE * TOLERANCE["weight_kg"]),
    }
    targets |= {g: Target(v, GIVEN_SCALE * TOLERANCE[g]) for g, v in given.items()}
    predictions = priors.predict(request.gender, request.height_cm, request.weight_kg, given)
    if "waist_cm" in given:  # the natural waist fixes what the iliac-crest prediction would guess
        predictions.pop("waist_iliac_cm", None)
    targets |= {g: Target(p.value_cm, p.sd_cm) for g, p in predictions.items()}
    return targets, {g: p.value_cm for g, p in predictions.items()}


def start_shape(model: BodyModel, request: BodyRequest) -> np.ndarray:
    """A start for the fit: height and weight phenotypes from linear rules of thumb, no local change."""
    bmi = request.weight_kg / (request.height_cm / 100.0) ** 2
    mix = np.array([START["male"], START["female"]])
    base, bmi0, per = (1.0 - request.gender) * mix[0] + request.gender * mix[1]
    shape = np.zeros(3 + model.n_local)
    shape[:3] = (
        request.gender,
        0.5 + (request.height_cm - base) / HEIGHT_CM_PER_UNIT,
        0.5 + (bmi - bmi0) / per,
    )
    return shape


def garment_code(model: BodyModel, marks: Landmarks, request: BodyRequest) -> np.ndarray:
    """beta ``(3,)``: the default-phenotype body of the shopper's gender, height and weight, the weight
    phenotype extrapolated past the box (up to ``SHAPE_BOUNDS``) where her BMI is beyond it. Inside the
    box this is ``shape_from_measurements`` itself; beyond it the box's heaviest (or lightest) body of
    her height is the start of the same Newton solve on the extended shape (``with_height_and_weight``),
    the height kept within the box's. The code the population drapes (``training.drape``) and the
    garment models are trained on."""
    lo, hi = supported_height_range_cm(model, request.gender)
    h = float(np.clip(request.height_cm, lo, hi))
    try:
        return shape_from_measurements(model, request.gender, h, request.weight_kg)
    except ShapeOutOfRange:
        pass
    shape = np.concatenate([garment_beta(model, request), np.zeros(model.n_local)])
    solved = with_height_and_weight(model, marks, shape, h, request.weight_kg)
    if solved is not None:
        return solved[:3].copy()
    # Heavier (or lighter) than the extended weight phenotype reaches: its bound, at her height.
    heavier = request.weight_kg > body_measurements(model.shape_vertices(shape), model.faces)[1]
    shape[2] = SHAPE_BOUNDS[2][1 if heavier else 0]
    for _ in range(NEWTON_STEPS):
        values, jac = evaluate(model, marks, shape, HW_ROWS[:1])
        shape[1] = np.clip(shape[1] - (values[0] - h) / jac[0, 1], *SHAPE_BOUNDS[1])
    return shape[:3].copy()


def garment_beta(model: BodyModel, request: BodyRequest) -> np.ndarray:
    """beta ``(3,)`` of the box body (``body.shape_from_measurements``) nearest in height, then weight:
    the garment code of the models before issue 55's population drapes, and ``garment_code``'s start."""
    lo, hi = supported_height_range_cm(model, request.gender)
    h = float(np.clip(request.height_cm, lo, hi))
    w_lo, w_hi = supported_weight_range_kg(model, request.gender, h)
    return shape_from_measurements(model, request.gender, h, float(np.clip(request.weight_kg, w_lo, w_hi)))


def build_body(
    model: BodyModel,
    marks: Landmarks,
    priors: GirthPriors,
    request: BodyRequest,
    table: BodyTable | None = None,
    press: bool = True,
) -> BuiltBody:
    """The shopper's body (module docstring); raises ``ShapeOutOfRange``. A request without girths is
    read from ``table`` when given (``body_table``, ~2 ms), fitted where the table has no body for it.
    ``press`` False: the fitted shape's mesh as it is, crossing or not (what the table stores: it is
    pressed when read).

    Two fits: the given measurements alone, then from there with the predicted girths too, kept when it
    still reproduces the given ones. Started cold with the predictions, the fit fell into a local
    minimum for heavy men whose hip is small for their weight (thighs +2, upper arms -2, 2 % of the
    weight missing: 19 of the first 575 NHANES men refused); from the first fit's body it does not."""
    request = check_request(priors, request)
    targets, predicted = targets_of(priors, request)
    given = ("height_cm", "weight_kg", *request.given)
    if table is not None and not request.given:
        built = _from_table(model, marks, table, request, predicted)
        if built is not None:
            return built
    hard = {n: targets[n] for n in given}
    try:
        first = fit_shape(model, marks, start_shape(model, request), hard, frozenset(given), BODY_EVALUATIONS)
    except ValueError as e:  # the start's landmarks not found: no body to offer
        lo, hi = weight_range_kg(request.height_cm)
        raise ShapeOutOfRange("weight_kg", f"no body could be built for {request}: {e}", (lo, hi)) from None
    if not first.reproduced and table is not None:
        first = min(first, _fit_from_table(model, marks, table, request, hard, given), key=lambda f: f.worst)
    fit = first
    if first.reproduced and len(targets) > len(hard):
        budget = BODY_EVALUATIONS - first.evaluations
        second = fit_shape(model, marks, first.shape, targets, frozenset(given), budget, first.measured)
        if second.reproduced:
            fit = second
    shape, vertices, pressed, measured = fit.shape, None, None, fit.measured
    if fit.reproduced:

        def refit(start: np.ndarray, aim_kg: float) -> np.ndarray | None:
            aimed = targets | {"weight_kg": Target(aim_kg, targets["weight_kg"].scale)}
            again = fit_shape(model, marks, start, aimed, frozenset(given), BODY_EVALUATIONS)
            return again.shape if again.reproduced else None

        done = pressed_body(model, fit.shape, request.weight_kg, refit, check=press)
        if done is not None:
            shape, vertices, pressed = done
            if pressed is not None:
                measured = measure(vertices, model.faces, marks)
    misses = [n for n in given if abs(getattr(measured, n) - targets[n].value)
              > TOLERANCE[n] * (targets[n].value if n == "weight_kg" else 1.0)]  # fmt: skip
    if not fit.reproduced or vertices is None or misses:
        misses = misses or ["weight_kg"]
        asked = ", ".join(f"{n}={targets[n].value:g}" for n in given)
        closest = ", ".join(f"{n}={getattr(measured, n):.1f}" for n in misses)
        field = misses[0]
        if field in GIRTHS:
            allowed = priors.possible_range(request.gender, field, request.height_cm, request.weight_kg)
        elif field == "weight_kg":  # as far as the body reached towards it
            lo, hi = weight_range_kg(request.height_cm)
            reached = measured.weight_kg
            allowed = (lo, reached) if request.weight_kg > reached else (reached, hi)
        else:
            allowed = HEIGHT_RANGE_CM
        message = f"no body has {', '.join(misses)} together as given ({asked}); closest built: {closest}"
        raise ShapeOutOfRange(field, message, allowed)
    code = garment_code(model, marks, request)
    return BuiltBody(shape, vertices, code, measured, predicted, tuple(request.given), fit, pressed)


def _fit_from_table(
    model, marks, table: BodyTable, request: BodyRequest, hard: dict, given: tuple
) -> BodyFit:
    """The given measurements' fit started from the table's body of the request's height and weight
    (no girth), where the rule-of-thumb start failed: from that start the fit of a 190 cm, 120 kg man
    with chest 123.5 and hip 127.5 cm stalled at its first step (every step raised the cost) and was
    refused, 12 kg short; from the table's body it reproduces them. Costs a refusal one more fit."""
    looked = table.lookup(request.gender, request.height_cm, request.weight_kg)
    shape = None if looked is None else with_height_and_weight(
        model, marks, looked[0], request.height_cm, request.weight_kg
    )
    try:
        if shape is not None:
            return fit_shape(model, marks, shape, hard, frozenset(given), BODY_EVALUATIONS)
    except ValueError:  # the start's landmarks not found
        pass
    return BodyFit(np.zeros(0), None, np.inf, 0)


def pressed_body(
    model: BodyModel, shape: np.ndarray, weight_kg: float, solve, check: bool = True
) -> tuple[np.ndarray, np.ndarray, Pressed | None] | None:
    """``(shape, vertices (V, 3), pressed)``: the body of ``shape (S,)`` with its crossing parts pressed
    into contact (``self_contact.press_contacts``; pressed None where nothing crosses, or ``check`` is
    False: known not to), its weight solved again by ``solve(shape, aim_kg) -> shape | None`` so that
    the pressed mesh weighs ``weight_kg`` (``PRESS_SOLVES``, ``PRESSED_WEIGHT_SHARE``); None when a
    solve fails."""
    faces, ignore = model.faces, model.template_crossings
    vertices = model.shape_vertices(shape)
    if not check or not len(self_crossings(vertices, faces, ignore)):
        return shape, vertices, None
    aim, offset = weight_kg, np.zeros_like(vertices)
    for attempt in range(PRESS_SOLVES + 1):
        # From the last pressing's offsets: the re-solved body crosses where it did (half the rounds).
        pressed = press_contacts(vertices + offset, faces, CONTACT_GAP_M, ignore)
        offset = pressed.vertices - vertices
        _, mass = body_measurements(pressed.vertices, faces)
        if abs(mass - weight_kg) <= PRESSED_WEIGHT_SHARE * weight_kg or attempt == PRESS_SOLVES:
            return shape, pressed.vertices, pressed
        aim += weight_kg - mass
        shape = solve(shape, aim)
        if shape is None:
            return None
        vertices = model.shape_vertices(shape)
    raise AssertionError("unreachable")


def _from_table(model, marks, table: BodyTable, request: BodyRequest, predicted: dict) -> BuiltBody | None:
    looked = table.lookup(request.gender, request.height_cm, request.weight_kg)
    if looked is None:
        return None
    shape, levels_m, may_cross = looked
    shape = with_height_and_weight(model, marks, shape, request.height_cm, request.weight_kg)
    if shape is None:
        return None

    def solve(start: np.ndarray, aim_kg: float) -> np.ndarray | None:
        return with_height_and_weight(model, marks, start, request.height_cm, aim_kg)

    done = pressed_body(model, shape, request.weight_kg, solve, check=may_cross)
    if done is None:
        return None
    shape, vertices, pressed = done
    read = pressed is None and request.gender in table.genders
    # The mesh is measured beside the outfit the request asks for (report only: the garments do not
    # need it): 3-25 ms off the request's path, a body without an outfit waits for it.
    measuring = _MEASURE_POOL.submit(_table_measurement, model, marks, vertices, levels_m if read else None)
    code = garment_code(model, marks, request)
    return BuiltBody(shape, vertices, code, measuring, predicted, (), None, pressed)


def _table_measurement(model, marks, vertices: np.ndarray, levels_m: np.ndarray | None) -> BodyMeasurements:
    """A table body's measurements: read at the table's ``levels_m``, or measured where they are None
    (a gender in between: its landmarks are not the mix of the sexes', its bust level ~2 cm off; a
    pressed body: its largest chest girth can move to another level, a BMI 53 man's 1.7 cm off) or a
    level finds no torso."""
    girths = None if levels_m is None else girths_at(model, marks, vertices, levels_m)
    if girths is not None:
        height_m, weight = body_measurements(vertices, model.faces)
        levels = dict(zip(LEVEL_COLUMNS, levels_m.tolist(), strict=True))
        return BodyMeasurements(100.0 * height_m, weight, *girths, levels_m=levels)
    return measure(vertices, model.faces, marks)


class BodyBuilder:
    """``build_body`` on one body model and its priors, the last ``BODY_CACHE`` bodies kept."""

    def __init__(
        self, model: BodyModel, priors: GirthPriors, table: BodyTable | None = None, press: bool = True
    ):
        self.model, self.priors, self.table, self.press = model, priors, table, press
        self.marks = landmarks(model)
        self.build = lru_cache(maxsize=BODY_CACHE)(self._build)

    def _build(self, request: BodyRequest) -> BuiltBody:
        return build_body(self.model, self.marks, self.priors, request, self.table, self.press)

    def ranges(self, gender: float, height_cm: float | None, weight_kg: float | None) -> dict:
        """What ``check_request`` accepts: heights, the weights at ``height_cm`` (clamped into the
        heights; their middle when None) and the girths at ``weight_kg`` (clamped likewise), each
        ``(lo, hi)`` as refusals print it."""
        g = float(np.clip(gender, 0.0, 1.0))
        h_lo, h_hi = printed_bounds(*HEIGHT_RANGE_CM)
        h = (h_lo + h_hi) / 2 if height_cm is None else min(max(height_cm, h_lo), h_hi)
        w_lo, w_hi = printed_bounds(*weight_range_kg(h))
        w = (w_lo + w_hi) / 2 if weight_kg is None else min(max(weight_kg, w_lo), w_hi)
        girths = {name: printed_bounds(*self.priors.possible_range(g, name, h, w)) for name in GIRTHS}
        return {
            "height_cm": (h_lo, h_hi),
            "weight_kg": (w_lo, w_hi),
            "at_height_cm": h,
            "at_weight_kg": w,
        } | girths
