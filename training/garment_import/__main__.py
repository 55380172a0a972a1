"""python -m training.garment_import FILE --id ID --name NAME --category top|bottom|dress ...

What ``ulnef garments import`` runs (it needs the training extra: torch, anny). Exit status 0 when
the garment is published, 2 for a file or argument the import cannot use (the message names the
file, the problem and the fix), 1 when an offline step failed (rerun to resume), 130 when
interrupted (rerun to resume).

``--job LIST.json`` takes the arguments from entry ``$JOB_COMPLETION_INDEX`` of a JSON list of
objects (``file``, ``id``, ``name``, ``category``, and optionally ``layer_rank``, ``units``): one pod
of a Kubernetes indexed Job per garment (``deploy/k8s-import/``).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
from pathlib import Path

from service.pipeline.catalog import load_catalog
from service.pipeline.tryon import GARMENT_ID, GARMENT_ID_RULE
from training.garment_import.pipeline import GarmentSpec, ImportSettings, import_garment
from training.garment_import.read import GarmentFileError

ID_PATTERN = re.compile(GARMENT_ID)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="ulnef garments import", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("file", type=Path, help="OBJ (+ MTL, textures) or glTF/GLB, draped on the avatar")
    p.add_argument("--id", required=True, help=f"catalog id: {GARMENT_ID_RULE}")
    p.add_argument("--name", required=True, help="name shown to shoppers")
    p.add_argument("--category", required=True, choices=("top", "bottom", "dress"))
    p.add_argument("--layer-rank", type=int, default=3,
                   help="how near the body it is worn by default, over the whole catalog: lower is nearer "
                   "(bundled: tank top 1, bottoms 2, T-shirt 3, long sleeve 4, jacket 5; "
                   "default: %(default)s)")  # fmt: skip
    p.add_argument("--units", choices=("m", "cm", "mm"), default="m", help="(default: %(default)s)")
    p.add_argument("--models", type=Path, default=None,
                   help="garments directory to publish into (default: ULNEF_GARMENTS_DIR)")  # fmt: skip
    s = ImportSettings()
    p.add_argument("--train-shapes", type=int, default=s.train_shapes, help="(default: %(default)s)")
    p.add_argument("--test-shapes", type=int, default=s.test_shapes, help="(default: %(default)s)")
    p.add_argument("--field-steps", type=int, default=s.field_steps, help="(default: %(default)s)")
    p.add_argument("--workers", type=int, default=s.workers, help="processes (default: %(default)s)")
    return p


def job_arguments(path: Path, index: int) -> list[str]:
    """The command line of entry ``index`` of the job list at ``path``."""
    entry = json.loads(Path(path).read_text())[index]
    argv = [str(entry["file"]), "--id", entry["id"], "--name", entry["name"], "--category", entry["category"]]
    for key in ("layer_rank", "units"):
        if key in entry:
            argv += [f"--{key.replace('_', '-')}", str(entry[key])]
    return argv


def fail(message: str) -> int:
    """Say why on stderr; the exit status of a file or argument the import cannot use."""
    print(f"ulnef garments import: {message}", file=sys.stderr)
    return 2


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--job"]:
        if len(argv) < 2 or "JOB_COMPLETION_INDEX" not in os.environ:
            return fail("--job LIST.json needs JOB_COMPLETION_INDEX (an indexed Job)")
        index = os.environ["JOB_COMPLETION_INDEX"]
        try:
            argv = job_arguments(Path(argv[1]), int(index)) + argv[2:]
        except (OSError, ValueError, KeyError, IndexError, TypeError) as e:
            return fail(f"{argv[1]}: no usable entry {index} ({type(e).__name__}: {e})")
    args = parser().parse_args(argv)
    directory = args.models or (Path(os.environ["ULNEF_GARMENTS_DIR"]) if os.environ.get("ULNEF_GARMENTS_DIR")
                                else None)  # fmt: skip
    if directory is None:
        return fail("no garments directory: pass --models DIR or set ULNEF_GARMENTS_DIR")
    if not ID_PATTERN.fullmatch(args.id):
        return fail(f"--id {args.id!r}: use {GARMENT_ID_RULE}")
    if args.id in load_catalog() or (directory / args.id).exists():
        return fail(f"--id {args.id!r} is already in the catalog: choose another id")
    if min(args.train_shapes, args.test_shapes, args.field_steps, args.workers) < 1:
        return fail("--train-shapes, --test-shapes, --field-steps and --workers must be at least 1")
    spec = GarmentSpec(args.id, args.name, args.category, args.layer_rank, args.units)
    settings = ImportSettings(args.train_shapes, args.test_shapes, args.field_steps, args.workers)
    try:
        import_garment(args.file, spec, directory, settings)
    except GarmentFileError as e:
        return fail(str(e))
    except RuntimeError as e:
        print(f"ulnef garments import: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("ulnef garments import: interrupted; rerun the same command to resume", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
