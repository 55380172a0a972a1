"""deploy/: the compose file and the Kubernetes manifests parse and keep their promises (probes on
routes the app has, non-root, read-only root filesystem, resources, HPA on the Deployment; in compose,
replicas reached only through the nginx proxy). tests/deploy/test_proxy.py runs deploy/nginx/."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import yaml

from service.server.settings import Settings
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
    writable = {m["mountPath"] for m in container["volumeMounts"] if not m.get("readOnly")}
    assert writable == {"/tmp"}


def test_access_control_is_on_and_fails_closed(k8s, container):
    env = {e["name"]: e for e in container["env"]}
    secret = k8s["Secret"]
    assert secret["metadata"]["name"] == "ulnef-access"
    assert set(secret["stringData"]) == {"keys.txt", "url-secret", "metrics-token"}
    # Shipped empty: the service refuses to start until the operator fills them.
    assert all(v == "" for v in secret["stringData"].values())
    mount = next(m for m in container["volumeMounts"] if m["name"] == "access")
    assert mount["readOnly"] is True
    (volume,) = [v for v in k8s["Deployment"]["spec"]["template"]["spec"]["volumes"] if v["name"] == "access"]
    assert volume["secret"]["secretName"] == "ulnef-access"
    files = {item["path"] for item in volume["secret"]["items"]}
    base = mount["mountPath"]
    assert env["ULNEF_API_KEYS_FILE"]["value"] == f"{base}/keys.txt" and "keys.txt" in files
    assert env["ULNEF_URL_SECRET_FILE"]["value"] == f"{base}/url-secret" and "url-secret" in files
    ref = env["ULNEF_METRICS_TOKEN"]["valueFrom"]["secretKeyRef"]
    assert ref == {"name": "ulnef-access", "key": "metrics-token"}
    for name in ("ULNEF_API_KEYS_FILE", "ULNEF_URL_SECRET_FILE", "ULNEF_METRICS_TOKEN"):
        assert name.removeprefix("ULNEF_").lower() in Settings.model_fields


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


@pytest.fixture(scope="module")
def compose() -> dict[str, dict]:
    """The services of deploy/compose.yaml: the replicas (built from the Dockerfile) and the proxy."""
    return yaml.safe_load((DEPLOY / "compose.yaml").read_text())["services"]


def replicas(compose: dict[str, dict]) -> dict[str, dict]:
    return {name: svc for name, svc in compose.items() if "build" in svc}


def test_compose_is_non_root_read_only_and_local(compose):
    assert len(replicas(compose)) >= 2 and set(compose) - set(replicas(compose)) == {"proxy"}
    for svc in [*replicas(compose).values(), compose["proxy"]]:
        assert svc["read_only"] is True and svc["cap_drop"] == ["ALL"]
        assert "no-new-privileges:true" in svc["security_opt"]
        assert any(t.startswith("/tmp") for t in svc["tmpfs"])
        assert int(svc["user"].split(":")[0]) != 0
        assert {"cpus", "memory"} <= set(svc["deploy"]["resources"]["limits"])
    for svc in replicas(compose).values():
        assert svc["build"]["dockerfile"] == "docker/Dockerfile"
        assert svc["user"] == "10001:10001"
        assert "ports" not in svc, "replicas are reached through the proxy only"
    assert all(p.startswith("127.0.0.1:") for p in compose["proxy"]["ports"])


def test_compose_proxy_fronts_every_replica(compose):
    """The proxy runs deploy/nginx/ (mounted read-only), its upstream lists every replica on the port
    the image listens on, it is published on the port its config listens on, and it starts once
    every replica is healthy (nginx resolves their names at start)."""
    proxy = compose["proxy"]
    (volume,) = proxy["volumes"]
    source, target, mode = volume.split(":")
    assert (DEPLOY / source).resolve() == DEPLOY / "nginx" and mode == "ro"
    assert proxy["entrypoint"][proxy["entrypoint"].index("-c") + 1] == f"{target}/nginx.conf"
    assert "-p" in proxy["entrypoint"] and proxy["entrypoint"][proxy["entrypoint"].index("-p") + 1] == "/tmp/"
    conf = (DEPLOY / "nginx" / "ulnef.conf").read_text()
    upstream = re.search(r"^upstream ulnef \{(.*?)^\}", conf, re.M | re.S).group(1)
    servers = re.findall(r"^\s*server (\S+?):(\d+)", upstream, re.M)
    assert {name for name, _ in servers} == set(replicas(compose))
    for name, port in servers:
        assert replicas(compose)[name]["expose"] == [port] and port == "8000"  # ULNEF_PORT of the image
    (listen,) = re.findall(r"^\s*listen (\d+);", conf, re.M)
    (published,) = proxy["ports"]
    assert published.rsplit(":", 1)[1] == listen
    assert proxy["depends_on"] == {name: {"condition": "service_healthy"} for name in replicas(compose)}


def test_proxy_limits_match_the_app():
    """nginx refuses what the app would refuse, and waits longer than the app's own time budget (so
    that the app's 504 with Retry-After is what a slow outfit gets)."""
    conf = (DEPLOY / "nginx" / "ulnef.conf").read_text()
    (body,) = re.findall(r"^\s*client_max_body_size (\d+)k;", conf, re.M)
    (read,) = re.findall(r"^\s*proxy_read_timeout (\d+)s;", conf, re.M)
    (message,) = re.findall(r"return 413 '(.*)\\n';", conf)
    defaults = {name: field.default for name, field in Settings.model_fields.items()}  # not the environment
    assert int(body) * 1024 == defaults["max_body_bytes"]
    assert f"at most {defaults['max_body_bytes']} bytes" in json.loads(message)["detail"]
    assert int(read) > defaults["request_timeout_s"]
