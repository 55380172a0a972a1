"""Where the committed models live. ``ULNEF_MODELS_DIR`` overrides (containers, tests)."""

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]


def models_dir() -> Path:
    return Path(os.environ.get("ULNEF_MODELS_DIR", REPO_ROOT / "models"))
