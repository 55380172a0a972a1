"""``ulnef garments import``: a garment made outside this project (``tests/garment_files.py``: a
swept tube, OBJ + MTL + PNG with a UV seam, and a GLB from trimesh's exporter) imported end to end
with tiny settings (few shapes, few steps), then served beside the bundled garments with its
texture; one test per validation error, asserting the exit status and the message."""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from service.cli import main as ulnef
from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.catalog import full_catalog, verified_imports
from service.pipeline.tryon import GARMENT_ID_MAX_CHARS
from service.process.manifest import verify_manifest
from tests.garment_files import skirt_tube, welded, write_glb, write_obj, write_plain_obj
from training.garment_import.__main__ import main as import_main
from training.garment_import.openings import name_openings
from training.garment_import.pipeline import GarmentSpec, prepare
from training.garment_import.read import read_garment

TINY = ["--train-shapes", "3", "--test-shapes", "2", "--field-steps", "60"]


@pytest.fixture(scope="module")
def body() -> BodyModel:
    return BodyModel.load()


@pytest.fixture(scope="module")
def floor(body) -> float:
    return float(body.vertices(np.asarray(DEFAULT_BETA))[:, 2].min())


@pytest.fixture(scope="module")
def tube(body):
    """A coarse tube (25 mm edges: fast to drape): vertices (Anny frame), faces, uv with the seam split."""
    return skirt_tube(body, edge=0.025)


@pytest.fixture(scope="module")
def imported(tmp_path_factory, tube, floor) -> Path:
    """The garments directory after a tiny import of the tube's OBJ in cm, through the CLI."""
    root = tmp_path_factory.mktemp("import")
    source = write_obj(root / "files", "wrap", *tube, units="cm", floor=floor)
    garments = root / "garments"
    code = ulnef(["garments", "import", str(source), "--id", "wrap_skirt", "--name", "Wrap skirt",
                  "--category", "bottom", "--units", "cm", "--models", str(garments), *TINY])  # fmt: skip
    assert code == 0
    return garments


@pytest.mark.slow  # a tiny import end to end: a minute or two on two cores
def test_a_tiny_import_publishes_a_verified_garment_and_nothing_else(imported: Path):
    assert sorted(p.name for p in imported.iterdir()) == ["wrap_skirt"]  # no staging left behind
    directory = imported / "wrap_skirt"
    assert verify_manifest(directory) == []
    record = json.loads((directory / "import.json").read_text())
    assert record["source"]["units"] == "cm" and record["garment"]["category"] == "bottom"
    assert set(record["held_out"]) == {"explicit_mm", "field_f_mm", "field_h_mm"}
    assert record["seconds"]["total"] > 0
    catalog = full_catalog(None, imported)
    garment = catalog["wrap_skirt"]
    assert garment.origin == "imported" and catalog["tshirt"].origin == "bundled"
    assert sorted(garment.openings) == ["hem", "waist"]
    assert garment.material.texture_files == {"base_color": "wrap_skirt.base.png"}


@pytest.mark.slow  # a tiny import end to end: a minute or two on two cores
def test_the_imported_garment_is_served_with_its_texture(imported: Path, tube, tmp_path: Path):
    from service.pipeline.tryon import ModelEngine, OutfitSpec
    from service.process.paths import models_dir
    from tests.pipeline.test_gltf_validator import validate

    dirs, broken = verified_imports(imported)
    assert broken == {}
    engine = ModelEngine.load(models_dir(), threads=2, imported=dirs)
    result = engine.make(OutfitSpec(("wrap_skirt", "tshirt"), gender=1.0, height_cm=165, weight_kg=60))
    assert result.report["garments_served"] == ["wrap_skirt", "tshirt"]
    assert result.report["numerical_fallback"] == []
    data = result.glb
    (n,) = struct.unpack("<I", data[12:16])
    doc = json.loads(data[20 : 20 + n])
    binary = data[20 + n + 8 :]
    mesh = next(m for m in doc["meshes"] if m["name"] == "wrap_skirt")["primitives"][0]
    accessor = doc["accessors"][mesh["attributes"]["TEXCOORD_0"]]
    view = doc["bufferViews"][accessor["bufferView"]]
    uv = np.frombuffer(binary, np.float32, accessor["count"] * 2, view["byteOffset"]).reshape(-1, 2)
    # The file's texture coordinates, every one of them, come back (glTF's v runs down).
    expected = np.unique(np.round(np.stack([tube[2][:, 0], 1 - tube[2][:, 1]], 1), 5), axis=0)
    np.testing.assert_allclose(np.unique(np.round(uv, 5), axis=0), expected, atol=2e-5)
    material = doc["materials"][mesh["material"]]
    texture = doc["textures"][material["pbrMetallicRoughness"]["baseColorTexture"]["index"]]
    image = doc["bufferViews"][doc["images"][texture["source"]]["bufferView"]]
    png = binary[image["byteOffset"] : image["byteOffset"] + image["byteLength"]]
    assert png == (imported / "wrap_skirt" / "garments" / "wrap_skirt.base.png").read_bytes()
    path = tmp_path / "imported.glb"
    path.write_bytes(data)
    assert validate([path])[str(path)]["numErrors"] == 0


@pytest.mark.slow  # a tiny import end to end: a minute or two on two cores
def test_the_garments_endpoint_lists_imports_and_leaves_out_a_broken_one(imported: Path, tmp_path: Path):
    from fastapi.testclient import TestClient

    from service.server.app import create_app
    from service.server.settings import Settings

    garments = tmp_path / "garments"
    shutil.copytree(imported / "wrap_skirt", garments / "wrap_skirt")
    shutil.copytree(imported / "wrap_skirt", garments / "other")
    (garments / "other" / "garments" / "wrap_skirt.base.png").write_bytes(b"changed")
    assert set(verified_imports(garments)[1]) == {"other"}
    settings = Settings(garments_dir=garments, verify_models=False, configure_logging=False)
    with TestClient(create_app(settings, engine_factory=lambda s: None)) as client:
        listed = {g["id"]: g for g in client.get("/v1/garments").json()["garments"]}
    assert listed["wrap_skirt"]["origin"] == "imported" and listed["tshirt"]["origin"] == "bundled"
    assert "other" not in listed and len(listed) == 8


def test_the_glb_file_imports_the_same_garment(tube, floor, body, tmp_path: Path):
    """Validation and reading only (the pipeline is the OBJ's): the GLB gives the same cloth."""
    glb = write_glb(tmp_path / "wrap.glb", *tube, floor=floor)
    obj = write_obj(tmp_path, "wrap", *tube, units="m", floor=floor)
    a, b = (read_garment(path, "m", floor, gid) for path, gid in ((glb, "a"), (obj, "b")))
    from scipy.spatial import cKDTree

    assert len(a.vertices) == len(b.vertices)
    assert cKDTree(b.vertices).query(a.vertices)[0].max() < 1e-6  # the same points (float32 vs 7 decimals)
    assert len(a.display.source) == len(b.display.source) > len(a.vertices)  # the seam split, both ways
    assert a.material.base_color == pytest.approx((1.0, 240 / 255, 230 / 255, 1.0))


def test_openings_are_named_by_where_they_sit(tube, body):
    v, f = welded(tube[0], tube[1])
    joints = dict(zip(body.bone_names, body.bone_heads, strict=True))
    bottom = name_openings(v, f, "bottom", joints)
    assert sorted(bottom) == ["hem", "waist"]
    assert v[bottom["waist"], 2].mean() > v[bottom["hem"], 2].mean()
    # Worn as a top, the upper loop is no neck (it sits at the waist): opening_1, the lower one the hem.
    assert sorted(name_openings(v, f, "top", joints)) == ["hem", "opening_1"]


def _fails(tmp_path: Path, capsys, path: Path, *extra: str, garment_id: str = "new_skirt") -> str:
    code = import_main([str(path), "--id", garment_id, "--name", "N", "--category", "bottom",
                        "--models", str(tmp_path / "garments"), *extra])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2, err
    assert not (tmp_path / "garments" / garment_id).exists()
    return err


def _plain(tmp_path: Path, name: str, vertices, faces, floor: float) -> Path:
    return write_plain_obj(tmp_path / f"{name}.obj", vertices, faces, floor)


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("pieces", "2 separate pieces"),
        ("non_manifold", "non-manifold edges"),
        ("degenerate", "degenerate faces"),
        ("duplicate", "duplicate faces"),
        ("inconsistent", "wound opposite ways"),
        ("closed", "a closed surface without openings"),
        ("far", "from the avatar"),
        ("deep", "inside the avatar"),
    ],
)
def test_each_validation_error_names_the_problem(case, message, tube, body, floor, tmp_path, capsys):
    v, f = welded(tube[0], tube[1])
    if case == "pieces":
        v, f = np.concatenate([v, v + [0.0, 0.0, -0.5]]), np.concatenate([f, f + len(v)])
    elif case == "non_manifold":
        v = np.concatenate([v, [v[f[0, 0]] + [0.0, -0.01, 0.0]]])
        f = np.concatenate([f, [[f[0, 0], f[0, 1], len(v) - 1]]])
    elif case == "degenerate":
        f = np.concatenate([f, [[f[0, 0], f[0, 0], f[0, 1]]]])
    elif case == "duplicate":
        f = np.concatenate([f, f[:3]])
    elif case == "inconsistent":
        f = f.copy()
        f[: len(f) // 2] = f[: len(f) // 2, ::-1]
    elif case == "closed":
        v, f = _closed_box(v)
    elif case == "far":
        v = v * 3.0
    elif case == "deep":
        centre = v.mean(0) * [1.0, 1.0, 0.0] + [0.0, 0.0, 1.0] * v
        v = centre + (v - centre) * [0.6, 0.6, 1.0]
    err = _fails(tmp_path, capsys, _plain(tmp_path, case, v, f, floor))
    assert message in err and f"{case}.obj" in err


@pytest.mark.parametrize(("edge", "word"), [(0.06, "coarse"), (0.003, "fine")])
def test_a_mesh_too_coarse_or_too_fine_is_remeshed_and_shown_as_made(edge, word, body, floor, tmp_path):
    """The simulation gets a ~12 mm mesh with the same openings; the display mesh is the file's (its
    UVs, its faces; a coarse one split 1-to-4 with its UVs interpolated) riding on it, where the file
    put it (a loose tube: nothing to push out of the body)."""
    from service.geometry.closest import ClosestPoint
    from service.geometry.mesh import edge_lengths, vertex_normals
    from training.garment_import.validate import EDGE_RANGE

    v, f, uv = skirt_tube(body, edge=edge, ease=(0.03, 0.06))
    path = write_obj(tmp_path / word, word, v, f, uv, units="m", floor=floor)
    file = read_garment(path, "m", floor, word)
    garment, notes = prepare(path, GarmentSpec(word, "X", "bottom", 3, "m"), body)
    assert any(f"too {word} for the simulation: remeshed" in n for n in notes)
    assert not any("pushed out" in n for n in notes)
    assert EDGE_RANGE[0] <= edge_lengths(garment.vertices, garment.faces).mean() <= EDGE_RANGE[1]
    assert sorted(garment.openings) == ["hem", "waist"]
    display = garment.display
    display.check(len(garment.vertices), garment.faces)
    if word == "fine":
        np.testing.assert_array_equal(display.faces, file.display.faces)
        np.testing.assert_array_equal(display.uv, file.display.uv)
    else:
        splits = round(np.log(len(display.faces) / len(file.display.faces)) / np.log(4))
        assert splits >= 1 and len(display.faces) == len(file.display.faces) * 4**splits
        # Interpolated UVs map the texture as before: the file's UV range, nothing new outside it.
        np.testing.assert_allclose(display.uv.min(0), file.display.uv.min(0), atol=1e-6)
        np.testing.assert_allclose(display.uv.max(0), file.display.uv.max(0), atol=1e-6)
    normals = vertex_normals(garment.vertices, garment.faces)
    placed, _ = display.place(garment.vertices, garment.faces, normals)
    off = ClosestPoint.build(file.vertices, file.faces).query(placed).distance
    assert off.max() < 1e-5  # float32 offsets; the coarse file's split vertices lie on its faces


def _closed_box(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A closed box around the tube's extent (no boundary at all)."""
    import trimesh

    box = trimesh.creation.box(extents=np.ptp(v, axis=0) + 0.02)
    box = box.subdivide_to_size(0.012)
    return np.asarray(box.vertices) + v.min(0) + np.ptp(v, axis=0) / 2, np.asarray(box.faces)


def test_flipped_and_shallow_cloth_are_fixed_and_said(tube, body, floor, tmp_path):
    from service.geometry.closest import ClosestPoint
    from service.geometry.mesh import vertex_normals

    v, f = welded(tube[0], tube[1])
    path = _plain(tmp_path, "flipped", v, f[:, ::-1], floor)
    garment, notes = prepare(path, GarmentSpec("x", "X", "bottom", 3, "m"), body)
    assert any("flipped" in n for n in notes) and any("pushed out" in n for n in notes)
    mean = body.vertices(np.asarray(DEFAULT_BETA))
    q = ClosestPoint.build(mean, body.faces).query(garment.vertices)
    assert q.signed.min() >= 0.004 - 1e-6
    normals = vertex_normals(garment.vertices, garment.faces)
    outward = np.einsum("nd,nd->n", normals, garment.vertices - q.point)
    assert np.mean(outward > 0) > 0.9


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["missing.obj"], "no such file"),
        (["skirt.stl"], "is not a garment format"),
        (["skirt.obj", "--id", "tshirt"], "already in the catalog"),
        (["skirt.obj", "--id", "Bad Id"], "--id 'Bad Id'"),
    ],
)
def test_bad_arguments_exit_2_with_a_message(args, message, tube, floor, tmp_path, capsys):
    write_plain_obj(tmp_path / "skirt.obj", *welded(tube[0], tube[1]), floor)
    (tmp_path / "skirt.stl").write_text("solid x\nendsolid x\n")
    path, *rest = args
    garment_id = rest[1] if rest else "new_skirt"
    err = _fails(tmp_path, capsys, tmp_path / path, *[a for a in rest if a not in ("--id", garment_id)],
                 garment_id=garment_id)  # fmt: skip
    assert message in err


RULE = "use 1-32 lower case letters, digits and _, starting with a letter"


@pytest.mark.parametrize("garment_id", ["a" * 33, "TShirt", "a" * GARMENT_ID_MAX_CHARS])
def test_ids_follow_the_apis_rule(garment_id, tmp_path, capsys):
    """One id rule for the import and the API (``service.pipeline.tryon.GARMENT_ID``): the longest id
    the API takes passes (the missing file is what is refused), one character more does not
    (tests/server/test_api_outfits.py: the API side)."""
    err = _fails(tmp_path, capsys, tmp_path / "missing.obj", garment_id=garment_id)
    if len(garment_id) > GARMENT_ID_MAX_CHARS or garment_id == "TShirt":
        assert err == f"ulnef garments import: --id {garment_id!r}: {RULE}\n"
    else:
        assert "--id" not in err and "missing.obj" in err


def test_no_garments_directory_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ULNEF_GARMENTS_DIR", raising=False)
    code = import_main([str(tmp_path / "x.obj"), "--id", "x", "--name", "X", "--category", "top"])
    assert code == 2 and "--models DIR or set ULNEF_GARMENTS_DIR" in capsys.readouterr().err


@pytest.mark.slow  # a tiny import end to end: a minute or two on two cores
def test_two_imports_at_once_both_publish(tube, floor, tmp_path: Path):
    """Two imports into one garments directory at the same time, as the pods of a Job would run
    them: each publishes its own directory and manifest (nothing shared to merge but the catalog the
    service assembles), and both are served."""
    import subprocess
    import sys

    source = write_obj(tmp_path / "files", "wrap", *tube, units="cm", floor=floor)
    garments = tmp_path / "garments"
    common = ["--category", "bottom", "--units", "cm", "--models", str(garments), *TINY, "--workers", "1"]
    runs = [
        subprocess.Popen([sys.executable, "-m", "training.garment_import", str(source), "--id", gid,
                          "--name", gid, *common], stdout=subprocess.DEVNULL)  # fmt: skip
        for gid in ("skirt_a", "skirt_b")
    ]
    assert [run.wait(timeout=900) for run in runs] == [0, 0]
    dirs, broken = verified_imports(garments)
    assert [d.name for d in dirs] == ["skirt_a", "skirt_b"] and broken == {}
    assert sorted(p.name for p in garments.iterdir()) == ["skirt_a", "skirt_b"]
    assert {"skirt_a", "skirt_b"} <= set(full_catalog(None, garments))
