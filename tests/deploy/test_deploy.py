"""deploy/: the compose file and the Kubernetes manifests parse and keep their promises (probes on
routes the app has, non-root, read-only root filesystem, resources, HPA on the Deployment)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tests.deploy.test_docker import app_paths

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"


@pytest.fixture(scope="module")
def k8s() -> dict[str, dict]:
    """Every manifest in deploy/k8s by kind (one object of each kind)."""
    files = sorted((DEPLOY / "k8s").glob("*.yaml"))
    docs = [d for p in files for d in yaml.safe_load_all(p.read_text()) if d]
    by_kind = {d["kind"]: d for d in docs}
    assert len(by_kind) == len(docs), "one object per kind"
    return by_kind


@pytest.fixture(scope="module")
def container(k8s) -> dict:
    (only,) = k8s["Deployment"]["spec"]["template"]["spec"]["containers"]
    return only


def test_kustomization_lists_every_manifest(k8s):
    files = {p.name for p in (DEPLOY / "k8s").glob("*.yaml")} - {"kustomization.yaml"}
    assert set(k8s["Kustomization"]["resources"]) == files


def test_probes_hit_app_routes(container):
    assert container["readinessProbe"]["httpGet"]["path"] == "/readyz"
    assert container["livenessProbe"]["httpGet"]["path"] == "/healthz"
    paths = {container[p]["httpGet"]["path"] for p in ("readinessProbe", "livenessProbe", "startupProbe")}
    assert paths <= app_paths()
    port_names = {p["name"] for p in container["ports"]}
    assert all(container[p]["httpGet"]["port"] in port_names for p in ("readinessProbe", "livenessProbe"))


def test_pod_is_non_root_with_read_only_root(k8s, container):
    pod = k8s["Deployment"]["spec"]["template"]["spec"]["securityContext"]
    assert pod["runAsNonRoot"] is True and pod["runAsUser"] == 10001
    ctx = container["securityContext"]
    assert ctx["readOnlyRootFilesystem"] is True
    assert ctx["allowPrivilegeEscalation"] is False and ctx["capabilities"]["drop"] == ["ALL"]
    assert {m["mountPath"] for m in container["volumeMounts"]} == {"/tmp"}


def test_resources_requested_and_limited(container):
    res = container["resources"]
    assert {"cpu", "memory"} <= set(res["requests"]) and {"cpu", "memory"} <= set(res["limits"])


def test_service_and_hpa_target_the_deployment(k8s, container):
    dep = k8s["Deployment"]
    labels = dep["spec"]["template"]["metadata"]["labels"]
    assert dep["spec"]["selector"]["matchLabels"].items() <= labels.items()
    svc = k8s["Service"]["spec"]
    assert svc["selector"].items() <= labels.items()
    assert svc["ports"][0]["targetPort"] in {p["name"] for p in container["ports"]}
    target = k8s["HorizontalPodAutoscaler"]["spec"]["scaleTargetRef"]
    assert (target["kind"], target["name"]) == ("Deployment", dep["metadata"]["name"])
    assert k8s["HorizontalPodAutoscaler"]["spec"]["minReplicas"] >= 1


def test_compose_is_non_root_read_only_and_local():
    (svc,) = yaml.safe_load((DEPLOY / "compose.yaml").read_text())["services"].values()
    assert svc["build"]["dockerfile"] == "docker/Dockerfile"
    assert svc["user"] == "10001:10001" and svc["read_only"] is True
    assert any(t.startswith("/tmp") for t in svc["tmpfs"])
    assert all(p.startswith("127.0.0.1:") for p in svc["ports"])
    assert svc["cap_drop"] == ["ALL"]
