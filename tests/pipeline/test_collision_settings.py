"""``service.pipeline.collisions.settings``: every tuned number of collision handling is one documented
field of ``CollisionSettings``, and no collision module keeps numbers of its own."""

from __future__ import annotations

import ast
from dataclasses import fields
from pathlib import Path

from service.pipeline.collisions.settings import SETTINGS, CollisionSettings

PACKAGE = Path(__file__).resolve().parents[2] / "service" / "pipeline" / "collisions"


def test_every_setting_has_a_docstring():
    tree = ast.parse((PACKAGE / "settings.py").read_text())
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "CollisionSettings")
    documented = set()
    for node, after in zip(cls.body, cls.body[1:], strict=False):
        if isinstance(node, ast.AnnAssign) and isinstance(after, ast.Expr):
            if isinstance(after.value, ast.Constant) and isinstance(after.value.value, str):
                documented.add(node.target.id)
    assert {f.name for f in fields(CollisionSettings)} - documented == set()


def test_no_collision_module_defines_a_number_of_its_own():
    # A module-level NAME = <number or tuple of numbers> outside settings.py is a tuned number out of place.
    found = []
    for path in sorted(PACKAGE.glob("*.py")):
        if path.name == "settings.py":
            continue
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.Assign | ast.AnnAssign):
                value = node.value
                numbers = [n for n in ast.walk(value) if isinstance(n, ast.Constant)] if value else []
                if numbers and all(isinstance(n.value, int | float) and not isinstance(n.value, bool)
                                   for n in numbers):  # fmt: skip
                    found.append(f"{path.name}:{node.lineno}")
    assert found == []


def test_the_clearance_is_the_drape_datasets():
    # The service cannot import training; the explicit meshes must be kept out of the body as the
    # drapes they were learned from were.
    from training.drape.dataset import CLEARANCE

    assert SETTINGS.clearance == CLEARANCE


def test_the_reach_and_the_first_room_derive_from_the_fields():
    from service.pipeline.quality import PENETRATION_BAND

    assert SETTINGS.reach == PENETRATION_BAND + SETTINGS.reach_pad
    assert SETTINGS.extra == SETTINGS.rooms[0] and list(SETTINGS.rooms) == sorted(set(SETTINGS.rooms))
