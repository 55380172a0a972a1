"""Import a shop's garment into a garments directory: validate it, then the paper's whole offline
part on it (drape dataset, explicit model, neural field, ONNX export), then publish it atomically.

Work happens in ``<garments dir>/.staging/<id>/``, a models directory of its own (the bundled body
linked in, the garment's catalog, and ``data/``, ``build/`` for the resumable steps), each step the
same command ``make models`` runs, with ``ULNEF_MODELS_DIR`` pointing there. A rerun with the same
file and settings resumes where the last one stopped. Only when every step has finished and the
garment has been served once in an outfit is ``<id>/`` (garment, explicit model, fields, manifest)
moved into the garments directory, in one rename: a failed or interrupted import leaves the
catalog as it was.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from service.pipeline.body import DEFAULT_BETA, BodyModel
from service.pipeline.catalog import Garment, save_garment
from service.process.manifest import file_sha256
from service.process.paths import models_dir
from training.garment_import.openings import name_openings
from training.garment_import.read import GarmentFileError, read_garment
from training.garment_import.remesh import needs_remesh, remesh_for_simulation
from training.garment_import.validate import EDGE_RANGE, check_topology, fit_to_body

STAGING = ".staging"
IMPORT_RECORD = "import.json"


@dataclass(frozen=True)
class ImportSettings:
    """How much offline work one import does (the defaults are the bundled garments')."""

    train_shapes: int = 14
    test_shapes: int = 8
    field_steps: int = 3000
    workers: int = 2


@dataclass(frozen=True)
class GarmentSpec:
    """What the shop says about the garment."""

    id: str
    name: str
    category: str
    layer_rank: int
    units: str


def prepare(path: Path, spec: GarmentSpec, body: BodyModel) -> tuple[Garment, list[str]]:
    """The catalog garment of the file at ``path`` (validated, fixed, openings named) and the notes."""
    floor = float(body.vertices(np.asarray(DEFAULT_BETA))[:, 2].min())
    source = read_garment(path, spec.units, floor, spec.id)
    check_topology(path, source)
    source, notes = fit_to_body(path, source, body)
    if (mean_edge := needs_remesh(source, EDGE_RANGE)) is not None:
        source, note = remesh_for_simulation(path, source, mean_edge)
        check_topology(path, source)
        source, again = fit_to_body(path, source, body)
        notes += [note, *again]
    joints = dict(zip(body.bone_names, body.bone_heads, strict=True))
    openings = name_openings(source.vertices, source.faces, spec.category, joints)
    if spec.category == "bottom" and "waist" not in openings:
        raise GarmentFileError(path, f"no waist opening found (openings: {sorted(openings)})",
                               "A bottom hangs from its waistband: check that the top loop goes "
                               "around the waist of the avatar.")  # fmt: skip
    if spec.category == "dress" and not ("hem" in openings and {"neck", "top"} & set(openings)):
        raise GarmentFileError(path, f"no neckline and hem found (openings: {sorted(openings)})",
                               "A dress hangs from the shoulders or the chest down around both legs: "
                               "check that its top loop goes around the neck or the chest of the avatar "
                               "and its hem around the legs.")  # fmt: skip
    garment = Garment(spec.id, spec.name, spec.category, spec.layer_rank, source.vertices, source.faces,
                      openings, source.display, source.material)  # fmt: skip
    return garment, notes


def _run(step: list[str], stage: Path, log) -> float:
    """Run one offline command in the staging directory; raises RuntimeError naming it if it fails."""
    t0 = time.perf_counter()
    path = os.pathsep.join(p for p in (str(_repo()), os.environ.get("PYTHONPATH", "")) if p)
    env = os.environ | {"ULNEF_MODELS_DIR": str(stage / "models"), "PYTHONPATH": path}
    log(f"$ python -m {' '.join(step)}")
    done = subprocess.run([sys.executable, "-m", *step], cwd=stage, env=env, check=False)
    if done.returncode != 0:
        command = f"python -m {' '.join(step)}"
        raise RuntimeError(f"step `{command}` failed (exit {done.returncode}); rerun the import to resume")
    return time.perf_counter() - t0


def _repo() -> Path:
    return Path(__file__).resolve().parents[2]


def _key(path: Path, spec: GarmentSpec, settings: ImportSettings) -> str:
    """What a staging directory was made from: a rerun with another file or settings starts afresh."""
    text = json.dumps([file_sha256(path), asdict(spec), asdict(settings)], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _stage(garments_dir: Path, garment: Garment, key: str) -> Path:
    stage = garments_dir / STAGING / garment.id
    marker = stage / "key"
    if stage.exists() and (not marker.is_file() or marker.read_text() != key):
        shutil.rmtree(stage)
    if not stage.exists():
        (stage / "models").mkdir(parents=True)
        os.symlink((models_dir() / "body").resolve(), stage / "models" / "body")
        marker.write_text(key)
    directory = stage / "models" / "garments"
    save_garment(directory, garment)
    (directory / "catalog.json").write_text(json.dumps({"garments": [garment.catalog_entry()]}, indent=2))
    return stage


def held_out_explicit_error_mm(stage: Path, garment_id: str) -> float:
    """Mean vertex error (mm) of the explicit model on the held-out drapes."""
    from service.pipeline.explicit import ExplicitModel
    from training.drape.dataset import load_split

    test = load_split(stage / "data" / "drapes", "test", garment_id)
    model = ExplicitModel.load(garment_id, stage / "models" / "explicit")
    pred = np.stack([model.canonical(b) for b in test["beta"]])
    return float(np.linalg.norm(pred - test["canonical"], axis=2).mean() * 1e3)


def serve_once(stage: Path, garment_id: str) -> dict:
    """Dress a held-out body in the staged garment alone with the service's pipeline; its report."""
    from service.pipeline.outfit import OutfitModels, make_outfit
    from training.drape.dataset import sample_betas

    models = OutfitModels.load(threads=2, imported=[stage / "models"])
    beta = sample_betas(1, 3)[0]
    outfit = make_outfit(models, [garment_id], beta)
    if not all(np.all(np.isfinite(v)) for _, v, _ in outfit.garments):
        raise RuntimeError("the imported garment's fitted mesh is not finite")
    return outfit.report


def publish(stage: Path, garments_dir: Path, garment_id: str, record: dict, log=print) -> Path:
    """Move the finished garment into ``garments_dir`` in one rename, with its manifest and record."""
    ready = stage / "publish" / garment_id
    shutil.rmtree(ready.parent, ignore_errors=True)
    for part in ("garments", "explicit", "fields"):
        shutil.copytree(stage / "models" / part, ready / part)
    (ready / IMPORT_RECORD).write_text(json.dumps(record, indent=2) + "\n")
    _run(["export.manifest", "--models-dir", str(ready)], stage, log)
    final = garments_dir / garment_id
    os.rename(ready, final)  # atomic within one filesystem: the garment appears whole or not at all
    shutil.rmtree(stage, ignore_errors=True)
    try:
        stage.parent.rmdir()  # only when no other import is staged there
    except OSError:
        pass
    return final


def import_garment(
    path: Path, spec: GarmentSpec, garments_dir: Path, settings: ImportSettings = ImportSettings(), log=print
) -> Path:
    """The whole import (see the module docstring); returns the published directory."""
    t_start = time.perf_counter()
    garments_dir = Path(garments_dir)
    garments_dir.mkdir(parents=True, exist_ok=True)
    body = BodyModel.load()
    garment, notes = prepare(Path(path), spec, body)
    for note in notes:
        log(f"fixed: {note}")
    log(f"{spec.id}: {len(garment.vertices)} vertices, {len(garment.faces)} faces, openings "
        f"{sorted(garment.openings)}" + ("" if garment.display is None else ", with UVs"))  # fmt: skip
    stage = _stage(garments_dir, garment, _key(Path(path), spec, settings))
    s = settings
    seconds = {"validate": time.perf_counter() - t_start}
    # An import drapes on the box (Sobol shapes and corners) within its budget per style: a few real
    # adults alone, two sexes apart, leave the mean body's in-between gender to extrapolation (a tiny
    # import's dress hem moved 5 cm there). Heavy shoppers get the extended code (decision 0023).
    seconds["drapes"] = _run(["training.drape", "--train", str(s.train_shapes), "--test", str(s.test_shapes),
                              "--workers", str(s.workers), "--garments", spec.id, "--out", "data/drapes",
                              "--source", "box"], stage, log)  # fmt: skip
    seconds["explicit"] = _run(["training.explicit", spec.id, "--data", "data/drapes"], stage, log)
    seconds["explicit"] += _run(["export.explicit", spec.id], stage, log)
    seconds["fields"] = _run(["training.fields", spec.id, "--steps", str(s.field_steps),
                              "--threads", str(s.workers)], stage, log)  # fmt: skip
    seconds["fields"] += _run(["export.fields", spec.id], stage, log)
    t0 = time.perf_counter()
    explicit_mm = held_out_explicit_error_mm(stage, spec.id)
    fields = json.loads((stage / "models" / "fields" / "fields.json").read_text())["fields"][spec.id]
    report = serve_once(stage, spec.id)
    seconds["verify"] = time.perf_counter() - t0
    seconds["total"] = time.perf_counter() - t_start
    record = {
        "source": {"file": Path(path).name, "sha256": file_sha256(Path(path)), "units": spec.units},
        "garment": asdict(spec),
        "settings": asdict(settings),
        "notes": notes,
        "held_out": {"explicit_mm": round(explicit_mm, 3), "field_f_mm": round(fields["held_out"]["f_mm"], 3),
                     "field_h_mm": round(fields["held_out"]["h_mm"], 3)},  # fmt: skip
        "check_outfit": {"collision_free": report.get("collision_free"),
                         "seconds": report["seconds"]["total"]},  # fmt: skip
        "seconds": {k: round(v, 1) for k, v in seconds.items()},
    }
    final = publish(stage, garments_dir, spec.id, record, log)
    log(f"held-out error: explicit model {explicit_mm:.2f} mm, field f {fields['held_out']['f_mm']:.2f} mm, "
        f"h {fields['held_out']['h_mm']:.2f} mm")  # fmt: skip
    steps = ", ".join(f"{k} {v:.0f} s" for k, v in seconds.items() if k != "total")
    log(f"import time: {seconds['total'] / 60:.1f} min ({steps})")
    log(f"published {final}")
    return final
