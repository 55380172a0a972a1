"""The try-on page in headless Chromium (playwright-core + Debian's chromium) on the committed models:
pick a T-shirt and shorts, press Dress, wait for the 3D view, screenshot it, check the pixels.

Refresh the committed screenshot: ``ULNEF_UPDATE_SCREENSHOT=1 .venv/bin/pytest tests/server/test_page.py``
(writes docs/images/page.png). Skipped without node/chromium except in CI, where it fails.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from service.process.paths import REPO_ROOT
from service.server.app import create_app
from service.server.settings import Settings
from tests.service_tools import CHROMIUM, live_server, require, require_node, run_node

SCREENSHOT = REPO_ROOT / "docs" / "images" / "page.png"


def share_above(rgb: np.ndarray, high: int, low: int, margin: int = 60) -> float:
    """Share of pixels of ``rgb (H, W, 3) uint8`` whose channel ``high`` exceeds ``low`` by ``margin``."""
    return float(np.mean(rgb[..., high].astype(int) > rgb[..., low].astype(int) + margin))


def test_page_dresses_a_body(tmp_path: Path):
    pytest.importorskip("onnxruntime")
    image = pytest.importorskip("PIL.Image")
    require_node("playwright-core")
    require(Path(CHROMIUM).exists(), f"chromium ({CHROMIUM})")
    settings = Settings(self_test_untangle=False, configure_logging=False, request_timeout_s=600)
    shot = tmp_path / "page.png"
    with live_server(create_app(settings)) as base:
        summary = json.loads(run_node("page.mjs", f"{base}/", str(shot), timeout=600,
                                      env={"PAGE_TIMEOUT_MS": "570000"}))  # fmt: skip
    assert summary["outside"] == [], "the page must not load anything from outside the server"
    assert summary["consoleErrors"] == []
    assert summary["layers"] == ["Shorts", "T-shirt"]
    assert summary["loaded"] is True, summary["status"]
    assert summary["src"].startswith("/v1/outfits.glb?garments=shorts,tshirt&")
    assert "shorts < tshirt" in summary["status"]
    rgb = np.asarray(image.open(shot).convert("RGB"))
    view = rgb[:, 320:]  # right of the controls column
    # The T-shirt (red, service.pipeline.gltf.COLORS) and the shorts (teal) are on screen.
    red, green = 0, 1
    assert share_above(view, red, green) > 0.02, "no T-shirt red in the 3D view"
    assert share_above(view, green, red) > 0.01, "no shorts teal in the 3D view"
    if os.environ.get("ULNEF_UPDATE_SCREENSHOT") == "1":
        shutil.copyfile(shot, SCREENSHOT)
