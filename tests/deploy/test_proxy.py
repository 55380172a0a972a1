"""Two real ``ulnef serve`` replicas behind Debian's nginx running ``deploy/nginx/`` (rendered for
loopback ports by ``deploy/nginx/render.py``).

The page's flow (POST /v1/outfits, then GET its ``glb_url``) is run ``FLOWS`` times through the
proxy; round robin sends the GET to the replica that did not make the outfit, which must answer 200
with the same bytes as the maker. Through the proxy, gzip applies to JSON and GLB and
``If-None-Match`` gets 304. Needs nginx (`make nginx` installs Debian's as root); skips without it
on a developer machine, fails in CI.
"""

from __future__ import annotations

import contextlib
import gzip
import importlib.util
import os
import re
import shutil
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import httpx
import pytest

from tests.service_tools import free_port, require, serve_processes, stop_process_group, wait_until

REPO = Path(__file__).resolve().parents[2]
NGINX = os.environ.get("NGINX") or shutil.which("nginx") or "/usr/sbin/nginx"
FLOWS = 20
# Replicas start faster without untangling the self-test outfit; one worker and thread each, as the
# two share this machine's cores with nginx and the test.
REPLICA_ENV = {"ULNEF_SELF_TEST_UNTANGLE": "false", "ULNEF_WORKERS": "1", "ULNEF_ONNX_THREADS": "1"}
GZIP = {"Accept-Encoding": "gzip"}
IDENTITY = {"Accept-Encoding": "identity"}


def load_render():
    """``deploy/nginx/render.py`` (a script, not a package module)."""
    spec = importlib.util.spec_from_file_location("nginx_render", REPO / "deploy" / "nginx" / "render.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.render


@dataclass
class Flow:
    """One POST /v1/outfits and the GET of its ``glb_url``, both through the proxy."""

    body: dict
    post: httpx.Response
    glb_url: str | None
    get: httpx.Response | None


@pytest.fixture(scope="module")
def nginx() -> str:
    require(os.access(NGINX, os.X_OK), f"nginx ({NGINX}; Debian package nginx)")
    return NGINX


@pytest.fixture(scope="module")
def replicas(nginx, tmp_path_factory) -> list[str]:
    t0 = time.perf_counter()
    with serve_processes(2, REPLICA_ENV, log_dir=tmp_path_factory.mktemp("replicas")) as urls:
        print(f"\n2 replicas ready in {time.perf_counter() - t0:.1f} s")
        yield urls


@contextmanager
def running_nginx(
    nginx: str, replicas: list[str], prefix: Path, read_timeout: str | None = None
) -> Iterator[str]:
    """nginx with the rendered deploy/nginx/ files in front of ``replicas`` (``host:port``) on a free
    loopback port, one worker (so that one client connection sees nginx's round robin in order);
    ``read_timeout`` replaces ``proxy_read_timeout``. Yields its URL once it accepts connections."""
    port = free_port()
    files = load_render()(replicas, f"127.0.0.1:{port}", workers="1")
    if read_timeout is not None:
        files["ulnef.conf"], n = re.subn(r"proxy_read_timeout \S+;", f"proxy_read_timeout {read_timeout};",
                                         files["ulnef.conf"])  # fmt: skip
        assert n == 1
    for name, text in files.items():
        (prefix / name).write_text(text)
    # As root, workers would run as `nobody`, which cannot write proxy_temp under pytest's 0700 tmp dir.
    main = "daemon off;" + (" user root;" if os.geteuid() == 0 else "")
    cmd = [nginx, "-p", f"{prefix}/", "-c", str(prefix / "nginx.conf"), "-g", main]
    log = prefix / "nginx.log"
    with log.open("wb") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    try:
        def answers() -> bool:
            assert proc.poll() is None, f"nginx exited ({proc.returncode}):\n{log.read_text()[-3000:]}"
            with contextlib.suppress(OSError):  # a bare connection: a request would take a round robin turn
                socket.create_connection(("127.0.0.1", port), timeout=2).close()
                return True
            return False

        wait_until(answers, 15, lambda: f"nginx answering:\n{log.read_text()[-3000:]}", interval=0.1)
        yield url
    finally:
        stop_process_group(proc)


@pytest.fixture(scope="module")
def proxy(nginx, replicas, tmp_path_factory) -> Iterator[str]:
    addrs = [u.removeprefix("http://") for u in replicas]
    with running_nginx(nginx, addrs, tmp_path_factory.mktemp("nginx")) as url:
        yield url


def upstream(response: httpx.Response, replicas: list[str]) -> str:
    """The replica URL that answered ``response`` through the proxy (its X-Upstream header)."""
    addr = response.headers.get("x-upstream", "")
    assert "," not in addr, f"nginx retried on another replica: {addr}"
    return f"http://{addr}"


def outfit_body(i: int) -> dict:
    """A cheap outfit with a body of its own per ``i``: no two flows hit a cache."""
    body = {"gender": 0.0 if i % 4 < 2 else 1.0, "height_cm": 160.0 + i, "weight_kg": 55.0 + i}
    return {"garments": ["shorts" if i % 2 else "tshirt"], "body": body}


@pytest.fixture(scope="module")
def flows(proxy) -> list[Flow]:
    """The page's flow ``FLOWS`` times; after every second flow one more request shifts the round robin
    so that POST and GET land on different replicas, the GETs on each replica in turn."""
    out = []
    t0 = time.perf_counter()
    with httpx.Client(base_url=proxy, timeout=60, headers=GZIP) as client:
        for i in range(FLOWS):
            body = outfit_body(i)
            post = client.post("/v1/outfits", json=body)
            url = post.json().get("glb_url") if post.status_code == 200 else None
            get = client.get(url) if url else None
            out.append(Flow(body, post, url, get))
            if i % 2:
                client.get("/healthz")
    print(f"\n{FLOWS} flows (POST + GET of glb_url) through nginx: {time.perf_counter() - t0:.1f} s")
    return out


def test_every_glb_url_answers_the_same_bytes_on_either_replica(flows, replicas):
    cross = {r: 0 for r in replicas}
    for flow in flows:
        assert flow.post.status_code == 200, flow.post.text
        assert flow.get is not None
        maker, server = upstream(flow.post, replicas), upstream(flow.get, replicas)
        assert flow.get.status_code == 200, (
            f"GET {flow.glb_url} on {server} (made on {maker}): {flow.get.status_code} {flow.get.text[:300]}"
        )
        assert flow.get.headers["content-type"] == "model/gltf-binary"
        assert flow.get.content[:4] == b"glTF"
        if server != maker:
            cross[server] += 1
        for replica in replicas:
            direct = httpx.get(replica + flow.glb_url, headers=IDENTITY, timeout=60)
            assert direct.status_code == 200, f"{replica}{flow.glb_url}: {direct.status_code}"
            assert direct.content == flow.get.content, f"{replica} answers other bytes for {flow.glb_url}"
    assert all(n > 0 for n in cross.values()), f"GETs of outfits another replica made, per replica: {cross}"
    print(f"\nGETs of an outfit the other replica made, per replica: {cross}")


def _raw(client: httpx.Client, method: str, url: str, **kwargs) -> tuple[httpx.Response, bytes]:
    """The response and its body as sent (not decompressed)."""
    with client.stream(method, url, **kwargs) as response:
        return response, b"".join(response.iter_raw())


def test_gzip_applies_to_json_and_glb(proxy, replicas, flows):
    flow = flows[0]
    for replica in replicas:  # each replica has the outfit cached: every answer below is the same
        assert httpx.post(replica + "/v1/outfits", json=flow.body).status_code == 200
    with httpx.Client(base_url=proxy, timeout=60) as client:
        post, sent = _raw(client, "POST", "/v1/outfits", json=flow.body, headers=GZIP)
        assert post.status_code == 200 and post.headers.get("content-encoding") == "gzip", post.headers
        assert "Accept-Encoding" in post.headers.get("vary", "")
        plain = httpx.post(upstream(post, replicas) + "/v1/outfits", json=flow.body, headers=IDENTITY)
        assert gzip.decompress(sent) == plain.content
        get, glb_sent = _raw(client, "GET", flow.glb_url, headers=GZIP)
        assert get.status_code == 200 and get.headers.get("content-encoding") == "gzip", get.headers
        assert "Accept-Encoding" in get.headers.get("vary", "")
        glb = gzip.decompress(glb_sent)
        assert glb == flow.get.content
        identity, glb_plain = _raw(client, "GET", flow.glb_url, headers=IDENTITY)
        assert "content-encoding" not in identity.headers and glb_plain == glb
    print(f"\ngzip through nginx: JSON {len(plain.content)} -> {len(sent)} B "
          f"({len(sent) / len(plain.content):.2f}), GLB {len(glb)} -> {len(glb_sent)} B "
          f"({len(glb_sent) / len(glb):.2f})")  # fmt: skip


@pytest.mark.parametrize("encoding", ["identity", "gzip"])
def test_if_none_match_gets_304_through_the_proxy(proxy, replicas, flows, encoding):
    """With gzip nginx sends the ETag weak (W/"..."); the client sends that back, and each of the
    two replicas (consecutive requests, round robin) must still answer 304."""
    url = flows[1].glb_url
    with httpx.Client(base_url=proxy, timeout=60, headers={"Accept-Encoding": encoding}) as client:
        first = client.get(url)
        assert first.status_code == 200
        etag = first.headers.get("etag")
        assert etag, f"no ETag on {url}: {dict(first.headers)}"
        assert etag.startswith("W/") == (encoding == "gzip"), etag
        answers = [client.get(url, headers={"If-None-Match": etag}) for _ in replicas]
    for answer in answers:
        assert answer.status_code == 304, f"{upstream(answer, replicas)}: {answer.status_code} for {etag}"
        assert answer.content == b""
    assert {upstream(a, replicas) for a in answers} == set(replicas)


def test_the_proxy_keeps_the_apps_limits(proxy):
    too_big = {"garments": ["tshirt"], "pad": "x" * 16_384}
    refused = httpx.post(proxy + "/v1/outfits", json=too_big)
    assert refused.status_code == 413 and "x-upstream" not in refused.headers  # nginx refused it itself
    assert refused.json()["detail"].startswith("request body too large: at most 16384 bytes")
    assert refused.json()["errors"][0]["field"] == "(request body)"  # the app's 413 shape
    assert httpx.get(proxy + "/metrics").status_code == 403
    assert httpx.post(proxy + "/v1/admin/reload").status_code == 403


@contextmanager
def silent_server() -> Iterator[str]:
    """A loopback ``host:port`` that accepts connections and reads requests but never answers: a
    replica stuck in a long computation."""
    listener = socket.create_server(("127.0.0.1", 0))
    held: list[socket.socket] = []
    stop = threading.Event()

    def accept():
        listener.settimeout(0.1)
        while not stop.is_set():
            with contextlib.suppress(TimeoutError, OSError):
                held.append(listener.accept()[0])

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    try:
        yield f"127.0.0.1:{listener.getsockname()[1]}"
    finally:
        stop.set()
        thread.join(5)
        for conn in [*held, listener]:
            conn.close()


def test_a_post_that_timed_out_is_not_sent_again_but_a_get_is(nginx, replicas, tmp_path):
    """A POST that reached a replica and timed out is answered 504, not computed a second time on the
    next replica; a GET that timed out is passed to the next replica. (A fresh nginx's round robin
    starts at the first server listed.)"""
    live = replicas[0].removeprefix("http://")
    with silent_server() as stuck, running_nginx(nginx, [stuck, live], tmp_path, "1s") as url:
        with httpx.Client(base_url=url, timeout=30) as client:
            post = client.post("/v1/outfits", json=outfit_body(0))  # the stuck replica
            assert post.status_code == 504 and post.headers["x-upstream"] == stuck
            assert post.json()["detail"].startswith("no replica answered") and post.headers["retry-after"]
            assert client.get("/healthz").headers["x-upstream"] == live
            get = client.get("/healthz")  # the stuck replica, then the live one
            assert get.status_code == 200 and get.headers["x-upstream"] == f"{stuck}, {live}"


def test_a_refused_connection_is_retried_for_a_post_too(nginx, replicas, tmp_path):
    """A replica that is down (connection refused) costs no request: the POST never reached it."""
    live = replicas[0].removeprefix("http://")
    closed = f"127.0.0.1:{free_port()}"  # nothing listens there
    with running_nginx(nginx, [closed, live], tmp_path) as url:
        post = httpx.post(url + "/v1/outfits", json=outfit_body(0), timeout=30)
        assert post.status_code == 200 and post.headers["x-upstream"] == f"{closed}, {live}"
        assert post.json()["glb_url"]
