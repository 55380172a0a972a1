"""The committed models' manifest: what ``models/`` must hold, byte for byte (stdlib only).

``models/manifest.json`` (written by ``python -m export.manifest``) lists every other file under
``models/`` with its size and sha256, so that a service start-up can refuse a half-copied or
stale model directory before it loads anything. Format::

    {
      "format_version": 1,
      "ulnef_version": "0.1.0",
      "producers": {"anny": "0.6.2", "numpy": "2.4.6"},
      "files": [{"path": "body/anny_shape.npz", "size": 123, "sha256": "..."}, ...]
    }

Paths are POSIX, relative to the models directory, sorted.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

MANIFEST_NAME = "manifest.json"
FORMAT_VERSION = 1
REFRESH_COMMAND = "python -m export.manifest"
_CHUNK = 1 << 20


@dataclass(frozen=True)
class ManifestEntry:
    """One listed file: ``path`` relative to the models directory (POSIX), size in bytes, hex sha256."""

    path: str
    size: int
    sha256: str


@dataclass(frozen=True)
class Manifest:
    """A parsed ``manifest.json``.

    ulnef_version: version of this package when the manifest was written.
    producers: versions of the tools the files came from, where known (e.g. ``anny``, ``numpy``).
    files: the listed files, sorted by path.
    """

    format_version: int
    ulnef_version: str
    producers: dict[str, str] = field(default_factory=dict)
    files: tuple[ManifestEntry, ...] = ()


def file_sha256(path: Path) -> str:
    """Hex sha256 of a file's bytes, read in chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def model_files(models_dir: Path | str) -> list[str]:
    """Relative POSIX paths of every file under ``models_dir`` except the manifest, sorted."""
    root = Path(models_dir)
    paths = (p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file())
    return sorted(p for p in paths if p != MANIFEST_NAME)


def _check_relative(path: str) -> str:
    pure = PurePosixPath(path)
    if not path or pure.is_absolute() or ".." in pure.parts or "\\" in path:
        raise ValueError(f"{MANIFEST_NAME}: file path {path!r} must be relative to the models directory")
    return path


def load_manifest(models_dir: Path | str) -> Manifest:
    """Read ``models_dir/manifest.json``.

    Raises FileNotFoundError if it is absent and ValueError if it is not a format-1 manifest.
    """
    path = Path(models_dir) / MANIFEST_NAME
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found; write it with `{REFRESH_COMMAND}`")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{path} is not valid JSON: {e}") from None
    if not isinstance(data, dict) or data.get("format_version") != FORMAT_VERSION:
        found = data.get("format_version") if isinstance(data, dict) else None
        raise ValueError(f"{path}: format_version must be {FORMAT_VERSION}, got {found!r}")
    try:
        files = tuple(
            ManifestEntry(path=_check_relative(str(e["path"])), size=int(e["size"]), sha256=str(e["sha256"]))
            for e in data["files"]
        )
        producers = {str(k): str(v) for k, v in data.get("producers", {}).items()}
        ulnef_version = str(data["ulnef_version"])
    except (KeyError, TypeError, AttributeError) as e:
        raise ValueError(f"{path}: malformed manifest ({type(e).__name__}: {e})") from None
    return Manifest(FORMAT_VERSION, ulnef_version, producers, files)


def verify_manifest(models_dir: Path | str) -> list[str]:
    """Human-readable problems with ``models_dir`` against its manifest; empty means OK.

    Reports an absent or unreadable manifest, and per file: listed but missing, size or sha256
    different from the manifest, present but unlisted.
    """
    root = Path(models_dir)
    try:
        manifest = load_manifest(root)
    except (FileNotFoundError, ValueError) as e:
        return [str(e)]
    problems = []
    listed = set()
    for entry in manifest.files:
        listed.add(entry.path)
        path = root / entry.path
        if not path.is_file():
            problems.append(f"{entry.path}: missing (listed in {MANIFEST_NAME}, not found in {root})")
            continue
        size = path.stat().st_size
        if size != entry.size:
            problems.append(f"{entry.path}: size mismatch (expected {entry.size} bytes, actual {size})")
        actual = file_sha256(path)
        if actual != entry.sha256:
            problems.append(f"{entry.path}: sha256 mismatch (expected {entry.sha256}, actual {actual})")
    for path in model_files(root):
        if path not in listed:
            problems.append(f"{path}: unlisted (present in {root}, not in {MANIFEST_NAME})")
    return problems
