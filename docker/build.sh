#!/usr/bin/env bash
# Build the service image and run it on this machine without a Docker daemon or Docker Hub:
# buildah/podman (Debian packages) with vfs storage and chroot isolation, on a Debian bookworm base
# made here with debootstrap. Then start the container read-only, wait for /readyz and print the
# build time, the image size and the readiness answer. See docker/README.md.
#
#   apt-get install -y buildah podman runc debootstrap      # once, as root
#   docker/build.sh                                     # from anywhere in the repository
#
# Environment (defaults): WORK=build/container (storage, rootfs, logs; git-ignored),
# IMAGE=localhost/ulnef:latest, BASE=localhost/ulnef-base:bookworm, PORT=18000 (127.0.0.1 only),
# MIRROR=http://deb.debian.org/debian, READY_TIMEOUT=300 (s), KEEP_RUNNING=0 (1: leave it running),
# SKIP_BUILD=0 (1: reuse the image), REF= (a git ref: build that commit, not the working tree).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

WORK=$(mkdir -p "${WORK:-build/container}" && cd "${WORK:-build/container}" && pwd)
IMAGE=${IMAGE:-localhost/ulnef:latest}
BASE=${BASE:-localhost/ulnef-base:bookworm}
PORT=${PORT:-18000}
MIRROR=${MIRROR:-http://deb.debian.org/debian}
READY_TIMEOUT=${READY_TIMEOUT:-300}
NAME=ulnef-smoke
STORE=(--root "$WORK/storage" --runroot "$WORK/run" --storage-driver vfs)

for tool in buildah podman runc debootstrap; do
    command -v "$tool" >/dev/null || { echo "build.sh: $tool missing (apt-get install -y $tool)" >&2; exit 1; }
done

# 1. Base: debootstrap's minimal bookworm + python3 (3.11) and venv; docs, caches and apt lists
#    dropped (copyright files kept). debootstrap removes $rootfs/debootstrap only when it succeeds.
if ! buildah "${STORE[@]}" inspect --type image "$BASE" >/dev/null 2>&1; then
    rootfs=$WORK/rootfs
    if [[ ! -x $rootfs/usr/bin/python3 || -d $rootfs/debootstrap ]]; then
        rm -rf "$rootfs"
        t0=$(date +%s)
        nice -n 10 debootstrap --variant=minbase --include=python3,python3-venv,ca-certificates \
            bookworm "$rootfs" "$MIRROR" >"$WORK/debootstrap.log" 2>&1
        echo "base: debootstrap took $(($(date +%s) - t0)) s"
    fi
    rm -rf "$rootfs"/var/lib/apt/lists/* "$rootfs"/var/cache/apt/* "$rootfs"/var/log/* \
        "$rootfs"/usr/share/man/* "$rootfs"/usr/share/info/* "$rootfs"/usr/share/locale/*
    find "$rootfs"/usr/share/doc -type f ! -name copyright -delete
    tar -C "$rootfs" -c . | podman "${STORE[@]}" import --quiet \
        --change 'ENV LANG=C.UTF-8' --change 'CMD ["python3"]' - "$BASE" >/dev/null
fi
echo "base: $BASE ($(podman "${STORE[@]}" image inspect --format '{{.Size}}' "$BASE" | awk '{printf "%.0f MB", $1/1e6}'))"

# 2. Image. pip inside the build reaches PyPI; where egress goes through a TLS-intercepting proxy
#    (as on this machine) the host's CA bundle is mounted for the build only (PIP_CERT build arg).
ca_args=()
host_ca=${PIP_CERT:-/etc/ssl/certs/ca-certificates.crt}
if [[ -f $host_ca ]]; then
    ca_args=(--volume "$host_ca:/etc/ssl/certs/build-ca.crt:ro" --build-arg PIP_CERT=/etc/ssl/certs/build-ca.crt)
fi
if [[ ${SKIP_BUILD:-0} == 1 ]] && buildah "${STORE[@]}" inspect --type image "$IMAGE" >/dev/null 2>&1; then
    build_s="(skipped)"
else
    context=.
    if [[ -n ${REF:-} ]]; then
        context=$WORK/context
        rm -rf "$context" && mkdir -p "$context"
        git archive "$REF" | tar -x -C "$context"
    fi
    t0=$(date +%s)
    nice -n 10 buildah "${STORE[@]}" bud --isolation chroot --format docker --pull=never \
        --build-arg BASE_IMAGE="$BASE" "${ca_args[@]}" \
        -f "$context/docker/Dockerfile" -t "$IMAGE" "$context" >"$WORK/build.log" 2>&1 \
        || { tail -40 "$WORK/build.log" >&2; exit 1; }
    build_s="in $(($(date +%s) - t0)) s"
fi
size=$(podman "${STORE[@]}" image inspect --format '{{.Size}}' "$IMAGE")
echo "image: $IMAGE built $build_s, $(awk -v s="$size" 'BEGIN {printf "%.0f MB", s/1e6}')"

# 3. Run it as compose/Kubernetes would: read-only root, tmpfs /tmp, no capabilities. Host network
#    with the server bound to 127.0.0.1 (no bridge or iptables needed inside a sandbox); explicit
#    rlimits no higher than the caller's (with every capability dropped, runc cannot raise them);
#    no systemd timer for the health check (it is run once below instead).
podman "${STORE[@]}" rm -f "$NAME" >/dev/null 2>&1 || true
t0=$(date +%s)
podman "${STORE[@]}" run --runtime runc --detach --name "$NAME" --network host \
    --read-only --tmpfs /tmp:rw,size=64m --cap-drop ALL --security-opt no-new-privileges \
    --ulimit "nofile=$(ulimit -Sn):$(ulimit -Hn)" --ulimit nproc=4096:4096 --health-interval disable \
    -e ULNEF_HOST=127.0.0.1 -e ULNEF_PORT="$PORT" -e ULNEF_REQUEST_TIMEOUT_S=600 "$IMAGE" 2> >(grep -v systemd >&2) >/dev/null
stop() { [[ ${KEEP_RUNNING:-0} == 1 ]] || podman "${STORE[@]}" rm -f "$NAME" >/dev/null 2>&1 || true; }
trap stop EXIT
ready=""
while (($(date +%s) - t0 < READY_TIMEOUT)); do
    if ready=$(python3 -c "import urllib.request as u; print(u.urlopen('http://127.0.0.1:$PORT/readyz', timeout=5).read().decode())" 2>/dev/null); then
        break
    fi
    if [[ $(podman "${STORE[@]}" inspect --format '{{.State.Running}}' "$NAME") != true ]]; then
        podman "${STORE[@]}" logs "$NAME" >&2; echo "build.sh: container exited" >&2; exit 1
    fi
    sleep 1
done
[[ -n $ready ]] || { podman "${STORE[@]}" logs "$NAME" >&2; echo "build.sh: /readyz not 200 after $READY_TIMEOUT s" >&2; exit 1; }
echo "run: /readyz 200 after $(($(date +%s) - t0)) s: $ready"
health=healthy
podman "${STORE[@]}" healthcheck run "$NAME" >/dev/null 2>&1 || health=unhealthy
rootfs_rw=read-only
podman "${STORE[@]}" exec "$NAME" touch /app/probe 2>/dev/null && rootfs_rw=WRITABLE
echo "run: user $(podman "${STORE[@]}" exec "$NAME" id -u), root filesystem $rootfs_rw, healthcheck $health"
# One outfit through the HTTP API, as the GLB itself (the pipeline is not interrupted: generous budget).
outfit=$(python3 - "$PORT" <<'PY'
import json, sys, time, urllib.request
body = {"garments": ["pants", "tshirt"], "body": {"gender": 0.3, "height_cm": 175, "weight_kg": 72}}
req = urllib.request.Request(f"http://127.0.0.1:{sys.argv[1]}/v1/outfits", json.dumps(body).encode(),
                             {"Content-Type": "application/json", "Accept": "model/gltf-binary"})
t0 = time.perf_counter()
glb = urllib.request.urlopen(req, timeout=600).read()
assert glb[:4] == b"glTF", glb[:100]
print(f"{time.perf_counter() - t0:.1f} s, GLB {len(glb) / 1e6:.1f} MB")
PY
) || { podman "${STORE[@]}" logs --tail 20 "$NAME" >&2; echo "build.sh: POST /v1/outfits failed" >&2; exit 1; }
echo "run: POST /v1/outfits pants,tshirt (cold): $outfit"
pid=$(podman "${STORE[@]}" inspect --format '{{.State.Pid}}' "$NAME")
echo "run: server RSS $(awk '/VmRSS/ {printf "%.0f MB", $2 * 1024 / 1e6}' "/proc/$pid/status")"
if [[ ${KEEP_RUNNING:-0} == 1 ]]; then
    echo "left running on 127.0.0.1:$PORT; stop: podman ${STORE[*]} rm -f $NAME"
fi
