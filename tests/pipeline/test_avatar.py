"""The avatar (``service/pipeline/avatar.py`` and ``ulnef avatar``): tape girths on shapes with known
answers, the mean body's measurements, and the files a design tool reads (GLB with UVs, OBJ in the
unit asked for, the JSON beside them), with the refusals of what cannot be written."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from service.cli import main
from service.pipeline.avatar import cross_section, mean_avatar, tape_girth
from service.pipeline.body import BodyModel, display_mesh
from service.pipeline.gltf import ANNY_TO_GLTF


def _prism(n: int, radius: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """A closed n-gon prism around the z axis, z in [0, height]."""
    a = 2 * np.pi * np.arange(n) / n
    ring = np.stack([radius * np.cos(a), radius * np.sin(a)], axis=1)
    v = np.concatenate([np.c_[ring, np.zeros(n)], np.c_[ring, np.full(n, height)]])
    i = np.arange(n)
    j = (i + 1) % n
    sides = np.concatenate([np.stack([i, j, n + j], 1), np.stack([i, n + j, n + i], 1)])
    return v, sides


def test_tape_girth_of_a_prism_is_its_perimeter():
    v, f = _prism(64, 0.15, 1.0)
    expected = 2 * 64 * 0.15 * np.sin(np.pi / 64)
    assert tape_girth(v, f, 0.37) == pytest.approx(expected, rel=1e-12)
    # Every triangle crossing the plane gives its two crossing edges (shared edges come twice).
    assert len(cross_section(v, f, 0.37)) == 2 * len(f)
    assert tape_girth(v, f, 1.5) == 0.0  # above the mesh


def test_tape_girth_spans_a_concavity():
    """Two prisms side by side: the tape runs around both, over the gap."""
    a, fa = _prism(32, 0.1, 1.0)
    b = a + [0.3, 0.0, 0.0]
    v, f = np.concatenate([a, b]), np.concatenate([fa, fa + len(a)])
    hull = 2 * 0.3 + 2 * 32 * 0.1 * np.sin(np.pi / 32)  # two straight runs + one polygon's perimeter
    assert tape_girth(v, f, 0.5) == pytest.approx(hull, rel=1e-3)


@pytest.fixture(scope="module")
def avatar():
    return mean_avatar(BodyModel.load())


def test_the_mean_body_measures_like_a_person(avatar):
    g, z = avatar.girths, avatar.girth_heights
    assert g["waist"] < g["chest"] and g["waist"] < g["hip"]
    assert 0.75 < g["waist"] < g["chest"] < 1.2 and 0.85 < g["hip"] < 1.25
    assert 0.0 < z["hip"] < z["waist"] < z["chest"] < avatar.height
    assert avatar.vertices[:, 2].min() == 0.0
    assert avatar.vertices[:, 2].max() == pytest.approx(avatar.height, abs=1e-6)


def test_body_uvs_are_a_display_mesh_of_its_faces():
    body = BodyModel.load()
    display = body.display
    display.check(body.n_vertices, body.faces)
    assert body.n_vertices <= len(display.source) < 1.2 * body.n_vertices
    assert display.uv.min() >= 0.0 and display.uv.max() <= 1.0
    # OBJ's v (origin bottom left) is flipped to glTF's (top left).
    faces = np.array([[0, 1, 2]])
    d = display_mesh(faces, np.array([[0, 1, 1]]), np.array([[0.25, 0.1], [0.5, 0.9]]))
    np.testing.assert_array_equal(d.source, [0, 1, 2])
    np.testing.assert_allclose(d.uv, [[0.25, 0.9], [0.5, 0.1], [0.5, 0.1]], atol=1e-7)


def test_avatar_files(tmp_path: Path, avatar, capsys):
    glb, obj = tmp_path / "avatar.glb", tmp_path / "cm" / "avatar.obj"
    assert main(["avatar", "-o", str(glb)]) == 0
    info = json.loads((tmp_path / "avatar.json").read_text())
    assert info["units"] == "m" and info["up_axis"] == "+Y" and info["file"] == "avatar.glb"
    assert info["girths"] == {k: round(v, 4) for k, v in avatar.girths.items()}
    scene = trimesh.load(io.BytesIO(glb.read_bytes()), file_type="glb", process=False)
    mesh = scene.geometry["avatar"]
    expected = avatar.vertices[avatar.display.source] @ ANNY_TO_GLTF.T
    np.testing.assert_allclose(mesh.vertices, expected, atol=1e-6)
    # trimesh reports v up (origin bottom left), glTF stores it down
    np.testing.assert_allclose(mesh.visual.uv, avatar.display.uv * [1, -1] + [0, 1], atol=1e-6)
    assert mesh.vertices[:, 1].min() == pytest.approx(0.0, abs=1e-6)  # Y up, feet on the floor
    assert main(["avatar", "-o", str(obj), "--units", "cm"]) == 0  # the folder is made
    info = json.loads((tmp_path / "cm" / "avatar.json").read_text())
    assert info["units"] == "cm" and info["height"] == pytest.approx(avatar.height * 100, abs=1e-3)
    loaded = trimesh.load(obj, process=False, maintain_order=True)
    assert len(loaded.faces) == len(avatar.faces)
    extent = loaded.vertices.max(0) - loaded.vertices.min(0)
    assert extent[1] == pytest.approx(avatar.height * 100, abs=1e-3)
    assert loaded.visual.uv is not None


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["-o", "avatar.fbx"], "must end in .glb or .obj"),
        (["-o", "avatar.glb", "--units", "cm"], "glTF is in metres by definition"),
    ],
)
def test_avatar_refuses_what_it_cannot_write(tmp_path: Path, capsys, args, message):
    args = [str(tmp_path / a) if a.startswith("avatar") else a for a in args]
    assert main(["avatar", *args]) == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
