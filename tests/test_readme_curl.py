"""Every curl example in the READMEs runs against a live server on the committed models.

Each ```sh block's curl commands (with their ``\\`` continuations and ``VAR=$(curl ...)`` lines) run
in one bash, in order, so a later command can use what an earlier one returned. A command expects
the status its ``# -> NNN`` comment names, and a 2xx without one. A block that sends
``Bearer example-shop-key`` runs against a server with API keys on (docs/operations.md, "Access control").
"""

from __future__ import annotations

import hashlib
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from service.process.paths import REPO_ROOT
from service.server.app import create_app
from service.server.settings import Settings
from tests.service_tools import live_server, require

READMES = [REPO_ROOT / "README.md", REPO_ROOT / "deploy" / "README.md", REPO_ROOT / "docker" / "README.md"]
SERVER = re.compile(r"(?:https?://)?(?:127\.0\.0\.1|localhost):8000")
EXAMPLE_KEY = "example-shop-key"
# curl reports each answer's status on stderr, leaving its output where the example sends it.
CURL = "curl() { command curl -sS -w '%{stderr}STATUS %{http_code}\\n' \"$@\"; }\n"


def curl_blocks(text: str) -> list[tuple[str, list[int | None]]]:
    """(script, expected status per curl call: None for any 2xx) of each sh block with a curl call."""
    blocks = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        lines = [line.strip() for line in block.splitlines()]
        script, expected, i = [], [], 0
        while i < len(lines):
            line = lines[i]
            if re.match(r"^([A-Z_]+=\$\()?curl\s", line):
                command = [line]
                while command[-1].endswith("\\") and i + 1 < len(lines):
                    i += 1
                    command.append(lines[i])
                script.append("\n".join(command))
                expected.append(None)
            elif line.startswith("# ->") and expected:
                status = re.match(r"# ->\s*(\d{3})\b", line)
                expected[-1] = int(status.group(1)) if status else expected[-1]
            i += 1
        if script:
            blocks.append(("\n".join(script), expected))
    return blocks


def examples() -> list[tuple[str, int, str, list]]:
    out = []
    for path in READMES:
        if path.is_file():
            for n, (script, expected) in enumerate(curl_blocks(path.read_text())):
                out.append((path.relative_to(REPO_ROOT).as_posix(), n, script, expected))
    return out


EXAMPLES = examples()


def test_the_readme_has_curl_examples_of_every_outfit_endpoint():
    text = "\n".join(script for _, _, script, _ in EXAMPLES)
    paths = ("/v1/outfits ", "/v1/outfits.glb", "/v1/bodies ", "/v1/garments", "/readyz", "/openapi.yaml")
    for needed in (*paths, "Bearer"):
        assert needed in text, f"no README curl example of {needed}"


@pytest.fixture(scope="module")
def servers(tmp_path_factory):
    """The plain server and one with API keys on (``EXAMPLE_KEY``), both on the committed models."""
    pytest.importorskip("onnxruntime")
    require(shutil.which("curl") is not None, "curl")
    work = tmp_path_factory.mktemp("keys")
    (work / "keys.txt").write_text(hashlib.sha256(EXAMPLE_KEY.encode()).hexdigest() + "\n")
    (work / "url-secret").write_text("readme-example-url-secret-0123456789\n")
    common = dict(self_test_untangle=False, configure_logging=False, request_timeout_s=300)
    plain = create_app(Settings(**common))
    access = dict(api_keys_file=work / "keys.txt", url_secret_file=work / "url-secret",
                  metrics_token="example-metrics-token")  # fmt: skip
    keyed = create_app(Settings(**common, **access))
    with live_server(plain, ready_timeout=300) as a, live_server(keyed, ready_timeout=300) as b:
        yield {"plain": a, "keyed": b}


@pytest.mark.parametrize(("readme", "n", "script", "expected"), EXAMPLES,
                         ids=[f"{r}#{n}" for r, n, _, _ in EXAMPLES])  # fmt: skip
def test_readme_curl_example(servers, tmp_path: Path, readme, n, script, expected):
    base = servers["keyed" if f"Bearer {EXAMPLE_KEY}" in script else "plain"]
    proc = subprocess.run(["bash", "-c", CURL + SERVER.sub(base, script)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600, check=False)  # fmt: skip
    statuses = [int(s) for s in re.findall(r"^STATUS (\d{3})$", proc.stderr, flags=re.M)]
    assert len(statuses) == len(expected), f"{readme} block {n}: ran {statuses}\n{script}\n{proc.stderr}"
    for status, want in zip(statuses, expected, strict=True):
        assert status == want if want else 200 <= status < 300, f"{readme} block {n}: {statuses}\n{script}"
    assert proc.returncode == 0, f"{readme} block {n}:\n{proc.stderr}"
    for glb in tmp_path.glob("*.glb"):  # a download is a GLB, never an error body written over it
        assert glb.read_bytes()[:4] == b"glTF", glb.name
