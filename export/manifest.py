"""Write ``models/manifest.json``: every committed model file with its size and sha256.

Refresh after changing anything under ``models/`` (``tests/process/test_manifest.py`` fails until then)::

    python -m export.manifest

The output is deterministic (no timestamps, sorted paths), so an unchanged ``models/`` gives an
unchanged manifest. The export is a contract plus a check: the written file is re-read with
``service.process.manifest.verify_manifest`` and the command fails if it reports anything.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
from pathlib import Path

import numpy as np

from service.process.manifest import (
    FORMAT_VERSION,
    MANIFEST_NAME,
    file_sha256,
    model_files,
    verify_manifest,
)
from service.process.paths import models_dir as default_models_dir

BODY_FILE = "body/anny_shape.npz"


def producer_versions(models_dir: Path) -> dict[str, str]:
    """Versions of what produced the files, where known.

    anny: read from the body npz (the version ``export.body`` exported it with).
    numpy: the version writing this manifest; the npz files do not record theirs.
    """
    producers = {"numpy": np.__version__}
    body = models_dir / BODY_FILE
    if body.is_file():
        with np.load(body, allow_pickle=False) as npz:
            if "anny_version" in npz.files:
                producers["anny"] = str(npz["anny_version"])
    return dict(sorted(producers.items()))


def build_manifest(models_dir: Path) -> dict:
    """The manifest of ``models_dir`` as a JSON-ready dict (see ``service.process.manifest``)."""
    files = [
        {"path": rel, "size": (models_dir / rel).stat().st_size, "sha256": file_sha256(models_dir / rel)}
        for rel in model_files(models_dir)
    ]
    return {
        "format_version": FORMAT_VERSION,
        "ulnef_version": importlib.metadata.version("ulnef"),
        "producers": producer_versions(models_dir),
        "files": files,
    }


def write_manifest(models_dir: Path) -> Path:
    """Write ``models_dir/manifest.json`` and check it; raises RuntimeError if it does not verify."""
    path = models_dir / MANIFEST_NAME
    path.write_text(json.dumps(build_manifest(models_dir), indent=2) + "\n", encoding="utf-8")
    problems = verify_manifest(models_dir)
    if problems:
        raise RuntimeError(f"{path} does not verify:\n" + "\n".join(problems))
    return path


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--models-dir", type=Path, default=None, help="default: ULNEF_MODELS_DIR, else models/"
    )
    args = parser.parse_args(argv)
    directory = args.models_dir if args.models_dir is not None else default_models_dir()
    path = write_manifest(directory)
    print(f"wrote {path} ({len(model_files(directory))} files)")


if __name__ == "__main__":
    main()
