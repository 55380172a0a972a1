"""The ``ulnef`` command line: ``serve``, ``garments``, ``outfit``, ``avatar``, ``openapi``."""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Sequence
from pathlib import Path

from service.process.jit_cache import seed_jit_cache
from service.server.app import CATALOG_NOT_LOADED, create_app, try_load_catalog
from service.server.routes.garments import catalog_sizes
from service.server.routes.page import openapi_yaml
from service.server.settings import Settings

TABLE_COLUMNS = (
    ("id", "id"),
    ("name", "name"),
    ("category", "category"),
    ("layer rank", "layer_rank"),
    ("vertices", "vertices"),
    ("faces", "faces"),
    ("openings", "openings"),
    ("sizes", "sizes"),
)


def render_openapi() -> str:
    """The app's OpenAPI schema as YAML, keys in FastAPI's order (stable across runs)."""
    return openapi_yaml(create_app(Settings()).openapi())


def format_table(rows: list[dict]) -> str:
    """Left-aligned text table of garment summaries (``Garment.summary()`` dicts)."""
    cells = [[h for h, _ in TABLE_COLUMNS]]
    for row in rows:
        values = (row[key] for _, key in TABLE_COLUMNS)
        cells.append([", ".join(v) if isinstance(v, list) else str(v) for v in values])
    widths = [max(len(r[i]) for r in cells) for i in range(len(TABLE_COLUMNS))]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in cells)


def cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from service.server.access import KeysFileError
    from service.server.logs import configure
    from service.server.runtime import ModelIntegrityError, check_models

    settings = Settings(host=args.host, port=args.port)
    configure(settings.log_level, settings.log_format)
    if settings.verify_models:
        try:
            check_models(settings)  # the app checks again on start; this gives a plain exit status
        except ModelIntegrityError as e:
            print(f"ulnef serve: {e}", file=sys.stderr)
            return 1
    try:
        app = create_app(settings)
    except KeysFileError as e:  # a broken keys file must not leave the outfit endpoints open
        print(f"ulnef serve: {e}", file=sys.stderr)
        return 1
    uvicorn.run(
        app, host=settings.host, port=settings.port, log_level=settings.log_level,
        log_config=None, limit_concurrency=settings.max_connections, timeout_graceful_shutdown=20,
    )  # fmt: skip
    return 0


def cmd_garments(args: argparse.Namespace) -> int:
    catalog = try_load_catalog(Settings())
    if catalog is None:
        print(f"ulnef: {CATALOG_NOT_LOADED} (set ULNEF_MODELS_DIR or build models/garments)", file=sys.stderr)
        return 1
    sizes = catalog_sizes(Settings())
    rows = [g.summary() | {"sizes": sizes.get(gid, [])} for gid, g in catalog.items()]
    print(json.dumps({"garments": rows}, indent=2) if args.json else format_table(rows))
    return 0


GIRTH_OPTIONS = {
    "chest_cm": "chest (men) or bust (women) girth, ISO 8559-1",
    "waist_cm": "natural waist girth, ISO 8559-1",
    "hip_cm": "hip girth at the buttocks, ISO 8559-1",
}
BODY_DEFAULTS = {"gender": 0.0, "height_cm": 178.0, "weight_kg": 75.0}


def option(name: str) -> str:
    """``height_cm`` -> ``--height-cm``."""
    return "--" + name.replace("_", "-")


def body_values(args: argparse.Namespace) -> dict[str, float | None]:
    """The body the options give: gender, height and weight (their defaults where not given) and the
    girths (None: predicted)."""
    values = {name: getattr(args, name) for name in (*BODY_DEFAULTS, *GIRTH_OPTIONS)}
    return values | {name: default for name, default in BODY_DEFAULTS.items() if values[name] is None}


def body_problem(args: argparse.Namespace) -> str | None:
    """What the served range refuses in the body options (``service.pipeline.body_build.check_request``:
    height, BMI, each girth given the others), found in milliseconds, or None. A combination of girths
    no body has is found only when the body is built."""
    from service.pipeline.body import ShapeOutOfRange
    from service.pipeline.body_build import BodyRequest, check_request
    from service.pipeline.girth_priors import GirthPriors

    try:
        check_request(GirthPriors.load(), BodyRequest(**body_values(args)))
    except ShapeOutOfRange as err:
        return f"{option(err.field)}: {err}"
    return None


def garment_tokens(text: str) -> tuple[tuple[str, ...], tuple[str | None, ...]]:
    """``--garments pants,tshirt:L`` -> (ids, sizes): each token ``id`` or ``id:SIZE`` (None: one size)."""
    tokens = [t.partition(":") for t in text.split(",") if t]
    return tuple(t[0] for t in tokens), tuple(t[2] if t[1] else None for t in tokens)


def outfit_input_problem(args: argparse.Namespace, catalog: dict | None) -> str | None:
    """What is wrong with ``ulnef outfit``'s arguments, found before the models load (seconds), or None."""
    from service.pipeline.outfit import MAX_GARMENTS
    from service.pipeline.tryon import GARMENT_ID, GARMENT_ID_RULE

    ids, sizes = (list(t) for t in garment_tokens(args.garments))
    if not 1 <= len(ids) <= MAX_GARMENTS:
        return f"--garments: give 1-{MAX_GARMENTS} comma-separated garment ids (`ulnef garments` lists them)"
    malformed = [g for g in ids if not re.fullmatch(GARMENT_ID, g)]
    if malformed:
        return f"--garments: {malformed[0]!r} is no garment id (ids are {GARMENT_ID_RULE})"
    unknown = [g for g in ids if catalog is not None and g not in catalog]
    if unknown:
        return f"--garments: unknown id(s) {unknown}; allowed: {', '.join(catalog)}"
    if len(set(ids)) != len(ids):
        return f"--garments: each id at most once, got {ids}"
    known = catalog_sizes(Settings())
    for gid, size in zip(ids, sizes, strict=True):
        if size is not None and size not in known.get(gid, []):
            has = ", ".join(known.get(gid, [])) or "none (it comes in one size)"
            return f"--garments: {gid!r} has no size {size!r}; its sizes: {has}"
    output = Path(args.output)
    if not output.parent.is_dir():
        return f"-o {output}: no such directory {output.parent}"
    return body_problem(args)


def refusal(err) -> str:
    """An ``InvalidField`` as the CLI names it: ``--height-cm: ...`` for ``body.height_cm``."""
    if err.field.startswith("garments"):
        return f"--garments: {err} (allowed: {err.allowed})"
    return f"{option(err.field.removeprefix('body.'))}: {err}"


def cmd_outfit(args: argparse.Namespace) -> int:
    """Dress a body, write the GLB, print the quality report (with ``body``, as built) as JSON."""
    from service.pipeline.catalog import verified_imports
    from service.pipeline.outfit import OutfitModels
    from service.pipeline.tryon import InvalidField, ModelEngine, OutfitSpec

    problem = outfit_input_problem(args, try_load_catalog(Settings()))
    if problem is not None:
        print(f"ulnef outfit: {problem}", file=sys.stderr)
        return 2
    models = OutfitModels.load(threads=args.threads, imported=verified_imports(Settings().garments_dir)[0])
    engine = ModelEngine(models, "cli")
    ids, sizes = garment_tokens(args.garments)
    spec = OutfitSpec(ids, **body_values(args), untangle=not args.no_untangle, include_body=not args.no_body,
                      untangler=args.untangler, sizes=sizes)  # fmt: skip
    try:
        engine.validate(spec)  # the order, and a combination of girths no body has
        result = engine.make(spec)
    except InvalidField as err:
        print(f"ulnef outfit: {refusal(err)}", file=sys.stderr)
        return 2
    except ValueError as err:
        print(f"ulnef outfit: {err}", file=sys.stderr)
        return 2
    try:
        Path(args.output).write_bytes(result.glb)
    except OSError as e:
        print(f"ulnef outfit: cannot write {args.output}: {e.strerror}", file=sys.stderr)
        return 2
    print(json.dumps(result.report, indent=2))
    return 0


def cmd_fit(args: argparse.Namespace) -> int:
    """Each size of a style on a body over the garments under it, and the size to buy, as JSON
    (``POST /v1/fit``'s answer)."""
    from service.pipeline.outfit import OutfitModels
    from service.pipeline.tryon import InvalidField, ModelEngine, OutfitSpec

    problem = body_problem(args)
    if problem is not None:
        print(f"ulnef fit: {problem}", file=sys.stderr)
        return 2
    engine = ModelEngine(OutfitModels.load(threads=args.threads), "cli")
    under = tuple(g for g in args.under.split(",") if g)
    try:
        answer = engine.fit(OutfitSpec(under, **body_values(args)), args.style)
    except InvalidField as err:
        body_field = option(err.field.removeprefix("body."))
        where = f"--{err.field}" if err.field in ("style", "under") else body_field
        print(f"ulnef fit: {where}: {err} (allowed: {err.allowed})", file=sys.stderr)
        return 2
    print(json.dumps(answer, indent=2))
    return 0


def cmd_avatar(args: argparse.Namespace) -> int:
    """Write the avatar a shop drapes its garments on (GLB or OBJ) and its measurements as JSON; with
    any body option, a shopper's body instead (``write_body``)."""
    from service.pipeline.appearance import Material
    from service.pipeline.avatar import SKIN, avatar_info, avatar_obj, mean_avatar
    from service.pipeline.body import BodyModel
    from service.pipeline.gltf import GltfLayer, outfit_glb

    out = Path(args.output)
    suffix = out.suffix.lower()
    shopper = any(getattr(args, name) is not None for name in (*BODY_DEFAULTS, *GIRTH_OPTIONS))
    if suffix not in (".glb", ".obj"):
        print(f"ulnef avatar: {out}: the file must end in .glb or .obj", file=sys.stderr)
        return 2
    if suffix == ".glb" and args.units != "m":
        print(f"ulnef avatar: {out}: glTF is in metres by definition; write .obj for --units {args.units}",
              file=sys.stderr)  # fmt: skip
        return 2
    if shopper:
        return write_body(args, out)
    avatar = mean_avatar(BodyModel.load())
    info = avatar_info(avatar, args.units, out.name)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        if suffix == ".glb":
            layer = GltfLayer("avatar", avatar.vertices, avatar.faces, avatar.display, Material(SKIN, 0.8))
            out.write_bytes(outfit_glb([layer]))
        else:
            out.write_text(avatar_obj(avatar, args.units))
        out.with_suffix(".json").write_text(json.dumps(info, indent=2) + "\n")
    except OSError as e:
        print(f"ulnef avatar: cannot write {out}: {e.strerror}", file=sys.stderr)
        return 2
    print(json.dumps(info, indent=2))
    return 0


def write_body(args: argparse.Namespace, out: Path) -> int:
    """A shopper's body (``service.pipeline.body_build``, as POST /v1/bodies builds it) to ``out``
    (.glb: one node ``body``, its measurements as glTF extras); prints ``{"body": ...}``."""
    from service.pipeline.body import BodyModel, ShapeOutOfRange
    from service.pipeline.body_build import BodyBuilder, BodyRequest
    from service.pipeline.girth_priors import GirthPriors
    from service.pipeline.gltf import GltfLayer, outfit_glb

    if out.suffix.lower() != ".glb":
        print(f"ulnef avatar: {out}: a shopper's body is written as .glb", file=sys.stderr)
        return 2
    problem = body_problem(args)
    if problem is not None:
        print(f"ulnef avatar: {problem}", file=sys.stderr)
        return 2
    model = BodyModel.load()
    try:
        built = BodyBuilder(model, GirthPriors.load()).build(BodyRequest(**body_values(args)))
    except ShapeOutOfRange as err:
        print(f"ulnef avatar: {option(err.field)}: {err}", file=sys.stderr)
        return 2
    report = {"body": built.report()}
    layer = GltfLayer("body", built.vertices, model.faces, extras=report)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_bytes(outfit_glb([layer]))
    except OSError as e:
        print(f"ulnef avatar: cannot write {out}: {e.strerror}", file=sys.stderr)
        return 2
    print(json.dumps(report, indent=2))
    return 0


def cmd_openapi(args: argparse.Namespace) -> int:
    text = render_openapi()
    if args.output == "-":
        sys.stdout.write(text)
    else:
        Path(args.output).write_text(text)
    return 0


def positive_int(text: str) -> int:
    """argparse type: a whole number of at least 1 (argparse's exit 2 names the option otherwise)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is less than 1")
    return value


def add_body_options(parser: argparse.ArgumentParser) -> None:
    """Gender, height, weight and the girths (``ulnef outfit``, ``ulnef avatar``): unset is None, the
    defaults of ``BODY_DEFAULTS`` (or predicted, for a girth) are filled in by ``body_values``."""
    parser.add_argument("--gender", type=float, help="0 male .. 1 female (default: 0)")
    parser.add_argument("--height-cm", type=float, help="135-210 (default: 178)")
    parser.add_argument("--weight-kg", type=float, help="BMI 13-70 at the height (default: 75)")
    for name, what in GIRTH_OPTIONS.items():
        parser.add_argument(option(name), type=float, help=f"{what}, cm (default: predicted from the rest)")


def build_parser() -> argparse.ArgumentParser:
    defaults = Settings()
    parser = argparse.ArgumentParser(prog="ulnef", description="ULNeF virtual try-on service.")
    sub = parser.add_subparsers(dest="command", required=True)

    serve = sub.add_parser("serve", help="run the HTTP service on the bundled models")
    serve.add_argument("--host", default=defaults.host, help="bind address (default: %(default)s)")
    serve.add_argument("--port", type=int, default=defaults.port, help="port (default: %(default)s)")
    serve.set_defaults(func=cmd_serve)

    garments = sub.add_parser(
        "garments", help="list the garment catalog; `ulnef garments import FILE ...` adds one (--help there)"
    )
    garments.add_argument("--json", action="store_true", help="print JSON, as GET /v1/garments answers")
    garments.set_defaults(func=cmd_garments)

    outfit = sub.add_parser("outfit", help="dress a body in garments (inner to outer) and write a GLB")
    outfit.add_argument("--garments", required=True,
                        help="comma-separated ids, inner to outer, each `id` or `id:SIZE` (tshirt:L)")
    add_body_options(outfit)
    outfit.add_argument("--untangler", choices=("neural", "reference"), default="neural")
    outfit.add_argument("--no-untangle", action="store_true", help="explicit meshes only (tangled)")
    outfit.add_argument("--no-body", action="store_true", help="leave the body out of the GLB")
    outfit.add_argument("--threads", type=positive_int, default=2,
                        help="onnxruntime threads (default: %(default)s)")  # fmt: skip
    outfit.add_argument("-o", "--output", default="outfit.glb", help="GLB path (default: %(default)s)")
    outfit.set_defaults(func=cmd_outfit)

    avatar = sub.add_parser(
        "avatar", help="write the avatar to drape garments on (GLB or OBJ) and its JSON; with body options, "
        "a shopper's body (GLB) and its measurements",
    )  # fmt: skip
    avatar.add_argument("-o", "--output", default="avatar.glb", help=".glb or .obj (default: %(default)s)")
    avatar.add_argument("--units", choices=("m", "cm", "mm"), default="m", help="(default: %(default)s)")
    add_body_options(avatar)
    avatar.set_defaults(func=cmd_avatar)

    fit = sub.add_parser("fit", help="each size of a style on a body, and the size to buy (JSON)")
    fit.add_argument("--style", required=True, help="a garment id with sizes (docs/fit.md)")
    fit.add_argument("--under", default="", help="comma-separated ids worn under it, inner first")
    add_body_options(fit)
    fit.add_argument("--threads", type=positive_int, default=2,
                     help="onnxruntime threads (default: %(default)s)")  # fmt: skip
    fit.set_defaults(func=cmd_fit)

    openapi = sub.add_parser("openapi", help="write the HTTP API's OpenAPI schema as YAML")
    openapi.add_argument("-o", "--output", default="-", help="output file, '-' for stdout (default: stdout)")
    openapi.set_defaults(func=cmd_openapi)
    return parser


def garments_import(argv: list[str]) -> int:
    """``ulnef garments import ...``: the offline pipeline, in its own process. It needs the training
    extra (torch, anny), which the serving image leaves out; the service never imports it."""
    import importlib.util
    import subprocess

    if importlib.util.find_spec("torch") is None or importlib.util.find_spec("training") is None:
        print("ulnef garments import: needs the training extra: pip install -e '.[train]' (torch==2.13.0 "
              "first, as the Makefile does); the serving image leaves it out", file=sys.stderr)
        return 2
    return subprocess.run([sys.executable, "-m", "training.garment_import", *argv], check=False).returncode


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:2] == ["garments", "import"]:
        return garments_import(argv[2:])
    args = build_parser().parse_args(argv)
    seed_jit_cache()  # before any compiled kernel runs (a no-op outside the images)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
