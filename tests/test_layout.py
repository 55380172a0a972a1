"""The import rule of ``docs/architecture.md``, read from the source (every ``import``, lazy ones too):

- inside ``service/``: ``server`` -> ``pipeline`` -> ``geometry`` -> ``process``, never back; the CLI
  (``service/cli.py``) sits on top and may use them all;
- nothing under ``service/`` imports torch, ``training``, ``export``, ``benchmarks`` or ``tests``;
- ``export`` reads ``training``'s networks, ``training`` never imports ``export`` (every network);
- at most 8 modules directly in ``service/``: the rest live in their layer.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# Lowest first: a module may import its own layer and the ones before it.
LAYERS = ("process", "geometry", "pipeline", "server")
TOP = len(LAYERS)  # service/cli.py and service/__init__.py
NEVER_IN_SERVICE = ("torch", "training", "export", "benchmarks", "tests")
MAX_TOP_MODULES = 8


def imported_modules(path: Path, package: str) -> list[tuple[int, str]]:
    """(line, dotted module) of every import in ``path``; ``package`` resolves relative imports.
    ``from a.b import c`` gives ``a.b.c`` (c may be a submodule; the layer is the same either way)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parent, base] if base else parent)
            found += [(node.lineno, f"{base}.{alias.name}" if base else alias.name) for alias in node.names]
    return found


def layer_of(module: str) -> int | None:
    """Rank of a ``service`` module (0 = process ... TOP = the CLI), None for anything else."""
    parts = module.split(".")
    if parts[0] != "service":
        return None
    if len(parts) > 1 and parts[1] in LAYERS:
        return LAYERS.index(parts[1])
    return TOP


def module_name(path: Path, root: Path) -> tuple[str, str]:
    """(dotted module, its package) of ``path`` under the source root ``root``."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    package = parts[:-1]  # of a module and of an __init__ alike
    return ".".join(package if parts[-1] == "__init__" else parts), ".".join(package)


def violations(root: Path) -> list[str]:
    """Every import under ``root/service``, ``root/training`` that breaks the rule, as readable lines."""
    bad = []
    for path in sorted((root / "service").rglob("*.py")):
        name, package = module_name(path, root)
        own = layer_of(name)
        for line, module in imported_modules(path, package):
            where = f"{path.relative_to(root)}:{line} imports {module}"
            if module.split(".")[0] in NEVER_IN_SERVICE:
                bad.append(f"{where}: service/ never imports {module.split('.')[0]}")
            theirs = layer_of(module)
            if theirs is not None and theirs > own:
                bad.append(f"{where}: {_layer_name(own)} may not import from {_layer_name(theirs)}")
    for path in sorted((root / "training").rglob("*.py")):
        name, package = module_name(path, root)
        for line, module in imported_modules(path, package):
            if module.split(".")[0] == "export":
                bad.append(f"{path.relative_to(root)}:{line} imports {module}: training never imports export")
    return bad


def _layer_name(rank: int) -> str:
    return "the CLI" if rank == TOP else f"service.{LAYERS[rank]}"


def test_imports_go_one_way():
    assert violations(REPO) == []


def test_service_has_only_its_layers_and_few_top_modules():
    top = sorted(p.name for p in (REPO / "service").glob("*.py"))
    assert len(top) <= MAX_TOP_MODULES, top
    packages = sorted(p.name for p in (REPO / "service").iterdir() if (p / "__init__.py").is_file())
    assert packages == sorted(LAYERS)


@pytest.mark.parametrize(
    ("path", "source", "expected"),
    [
        ("service/geometry/mesh.py", "from service.pipeline.fit import x\n",
         "service/geometry/mesh.py:1 imports service.pipeline.fit.x: service.geometry may not import from "
         "service.pipeline"),
        ("service/geometry/mesh.py", "def f():\n    from ..pipeline import fit\n",
         "service/geometry/mesh.py:2 imports service.pipeline.fit: service.geometry may not import from "
         "service.pipeline"),
        ("service/pipeline/fit.py", "import service.server.app\n",
         "service/pipeline/fit.py:1 imports service.server.app: service.pipeline may not import from "
         "service.server"),
        ("service/process/paths.py", "from service import cli\n",
         "service/process/paths.py:1 imports service.cli: service.process may not import from the CLI"),
        ("service/pipeline/fields.py", "import torch\n",
         "service/pipeline/fields.py:1 imports torch: service/ never imports torch"),
        ("training/untangler.py", "from export.untangler import export\n",
         "training/untangler.py:1 imports export.untangler.export: training never imports export"),
    ],
)
def test_the_rule_names_a_backward_import(tmp_path: Path, path: str, source: str, expected: str):
    for d in ("service", "training"):
        (tmp_path / d).mkdir()
    (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
    (tmp_path / path).write_text(source)
    assert violations(tmp_path) == [expected]


def test_downward_and_same_layer_imports_pass(tmp_path: Path):
    (tmp_path / "training").mkdir()
    files = {
        "service/cli.py": "from service.server.app import create_app\n",
        "service/server/app.py": "from service.pipeline.outfit import x\nfrom . import errors\n",
        "service/pipeline/outfit.py": "from service.geometry.closest import y\nfrom .fit import z\n",
        "service/geometry/closest.py": "from service.process.threads import pool\n",
        "training/untangler.py": "from service.pipeline.untangle import untangle\n",
    }
    for path, source in files.items():
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(source)
    assert violations(tmp_path) == []


def test_the_architecture_map_names_files_that_exist():
    """``docs/architecture.md`` stays true: every path, module file and ``python -m`` it names exists."""
    import re

    text = (REPO / "docs" / "architecture.md").read_text()
    missing = []
    for token in set(re.findall(r"(?:service|training|export|tests|benchmarks|models|docs)/[\w/.]*", text)):
        if not (REPO / token.rstrip(".")).exists():
            missing.append(token)
    for name in set(re.findall(r"(?<![\w/])(\w+\.py)\b", text)):
        if not any((REPO / "service").rglob(name)):
            missing.append(name)
    for module in set(re.findall(r"python -m (\w+(?:\.\w+)*)", text)):
        path = REPO.joinpath(*module.split("."))
        if not (path.with_suffix(".py").is_file() or (path / "__main__.py").is_file()):
            missing.append(f"python -m {module}")
    assert sorted(missing) == []
