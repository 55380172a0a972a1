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
    rows = [g.summary() for g in catalog.values()]
    print(json.dumps({"garments": rows}, indent=2) if args.json else format_table(rows))
    return 0


def outfit_input_problem(args: argparse.Namespace, catalog: dict | None) -> str | None:
    """What is wrong with ``ulnef outfit``'s arguments, found before the models load (seconds), or None."""
    from service.pipeline.body import BodyModel, ShapeOutOfRange, shape_from_measurements
    from service.pipeline.outfit import MAX_GARMENTS
    from service.pipeline.tryon import GARMENT_ID, GARMENT_ID_RULE

    ids = [g for g in args.garments.split(",") if g]
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
    output = Path(args.output)
    if not output.parent.is_dir():
        return f"-o {output}: no such directory {output.parent}"
    try:
        shape_from_measurements(BodyModel.load(), args.gender, args.height_cm, args.weight_kg)
    except ShapeOutOfRange as err:
        return f"--{err.field.replace('_', '-')}: {err}"
    return None


def cmd_outfit(args: argparse.Namespace) -> int:
    """Dress a body, write the GLB, print the quality report as JSON."""
    from service.pipeline.body import ShapeOutOfRange, shape_from_measurements
    from service.pipeline.catalog import verified_imports
    from service.pipeline.gltf import outfit_glb
    from service.pipeline.outfit import OutfitModels, make_outfit
    from service.pipeline.tryon import glb_layers

    problem = outfit_input_problem(args, try_load_catalog(Settings()))
    if problem is not None:
        print(f"ulnef outfit: {problem}", file=sys.stderr)
        return 2
    models = OutfitModels.load(threads=args.threads, imported=verified_imports(Settings().garments_dir)[0])
    ids = [g for g in args.garments.split(",") if g]
    try:
        beta = shape_from_measurements(models.body, args.gender, args.height_cm, args.weight_kg)
        outfit = make_outfit(models, ids, beta, not args.no_untangle, args.untangler)
    except (ShapeOutOfRange, ValueError) as err:
        print(f"ulnef outfit: {err}", file=sys.stderr)
        return 2
    body = None if args.no_body else (outfit.body_vertices, outfit.body_faces)
    try:
        Path(args.output).write_bytes(outfit_glb(glb_layers(outfit.garments, models.catalog, body)))
    except OSError as e:
        print(f"ulnef outfit: cannot write {args.output}: {e.strerror}", file=sys.stderr)
        return 2
    print(json.dumps(outfit.report, indent=2))
    return 0


def cmd_avatar(args: argparse.Namespace) -> int:
    """Write the avatar a shop drapes its garments on (GLB or OBJ) and its measurements as JSON."""
    from service.pipeline.appearance import Material
    from service.pipeline.avatar import SKIN, avatar_info, avatar_obj, mean_avatar
    from service.pipeline.body import BodyModel
    from service.pipeline.gltf import GltfLayer, outfit_glb

    out = Path(args.output)
    suffix = out.suffix.lower()
    if suffix not in (".glb", ".obj"):
        print(f"ulnef avatar: {out}: the file must end in .glb or .obj", file=sys.stderr)
        return 2
    if suffix == ".glb" and args.units != "m":
        print(f"ulnef avatar: {out}: glTF is in metres by definition; write .obj for --units {args.units}",
              file=sys.stderr)  # fmt: skip
        return 2
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
    outfit.add_argument("--garments", required=True, help="comma-separated ids, inner to outer")
    outfit.add_argument("--gender", type=float, default=0.0, help="0 male .. 1 female (default: %(default)s)")
    outfit.add_argument("--height-cm", type=float, default=178.0, help="(default: %(default)s)")
    outfit.add_argument("--weight-kg", type=float, default=75.0, help="(default: %(default)s)")
    outfit.add_argument("--untangler", choices=("neural", "reference"), default="neural")
    outfit.add_argument("--no-untangle", action="store_true", help="explicit meshes only (tangled)")
    outfit.add_argument("--no-body", action="store_true", help="leave the body out of the GLB")
    outfit.add_argument("--threads", type=positive_int, default=2,
                        help="onnxruntime threads (default: %(default)s)")  # fmt: skip
    outfit.add_argument("-o", "--output", default="outfit.glb", help="GLB path (default: %(default)s)")
    outfit.set_defaults(func=cmd_outfit)

    avatar = sub.add_parser("avatar", help="write the avatar to drape garments on (GLB or OBJ) and its JSON")
    avatar.add_argument("-o", "--output", default="avatar.glb", help=".glb or .obj (default: %(default)s)")
    avatar.add_argument("--units", choices=("m", "cm", "mm"), default="m", help="(default: %(default)s)")
    avatar.set_defaults(func=cmd_avatar)

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
