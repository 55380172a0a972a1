#!/usr/bin/env bash
# Build the garment-import image (docker/Dockerfile.import) with buildah on the base docker/build.sh
# makes, then run one tiny import inside it as a Kubernetes Job pod would: read-only root, no
# network, no capabilities, the garments volume the only writable place. Prints build time, image
# size, the import's output and whether the published garment matches its manifest.
#
#   docker/build.sh            # once: the base image (and the serving image)
#   docker/build_import.sh
#
# Environment (defaults): WORK=build/container, IMAGE=localhost/ulnef-import:latest,
# BASE=localhost/ulnef-base:bookworm, WHEELS=/opt/wheels (a folder holding the torch CPU wheel, for
# machines that reach PyPI only; without it pip takes torch from the CPU wheels' index),
# PYTHON=.venv/bin/python (makes the test garment and checks the manifest), SKIP_BUILD=0 (1: reuse the image).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

WORK=$(mkdir -p "${WORK:-build/container}" && cd "${WORK:-build/container}" && pwd)
IMAGE=${IMAGE:-localhost/ulnef-import:latest}
BASE=${BASE:-localhost/ulnef-base:bookworm}
WHEELS=${WHEELS:-/opt/wheels}
PYTHON=${PYTHON:-.venv/bin/python}
STORE=(--root "$WORK/storage" --runroot "$WORK/run" --storage-driver vfs)

buildah "${STORE[@]}" inspect --type image "$BASE" >/dev/null 2>&1 \
    || { echo "build_import.sh: no base image $BASE: run docker/build.sh first" >&2; exit 1; }
args=(--build-arg BASE_IMAGE="$BASE")
host_ca=${PIP_CERT:-/etc/ssl/certs/ca-certificates.crt}
[[ -f $host_ca ]] && args+=(--volume "$host_ca:/etc/ssl/certs/build-ca.crt:ro" --build-arg PIP_CERT=/etc/ssl/certs/build-ca.crt)
if ls "$WHEELS"/torch-*+cpu-*.whl >/dev/null 2>&1; then
    args+=(--volume "$WHEELS:/wheels:ro" --build-arg PIP_FIND_LINKS=/wheels --build-arg PIP_EXTRA_INDEX_URL=)
fi
if [[ ${SKIP_BUILD:-0} == 1 ]] && buildah "${STORE[@]}" inspect --type image "$IMAGE" >/dev/null 2>&1; then
    built="(build skipped)"
else
    t0=$(date +%s)
    nice -n 10 buildah "${STORE[@]}" bud --isolation chroot --format docker --pull=never "${args[@]}" \
        -f docker/Dockerfile.import -t "$IMAGE" . >"$WORK/build_import.log" 2>&1 \
        || { tail -40 "$WORK/build_import.log" >&2; exit 1; }
    built="built in $(($(date +%s) - t0)) s"
fi
size=$(podman "${STORE[@]}" image inspect --format '{{.Size}}' "$IMAGE")
echo "image: $IMAGE $built, $(awk -v s="$size" 'BEGIN {printf "%.0f MB", s/1e6}')"

files=$WORK/import-files garments=$WORK/import-garments
rm -rf "$files" "$garments" && mkdir -p "$files" "$garments"
"$PYTHON" -m tests.garment_files "$files" --edge 0.025 --units cm >/dev/null
chown 10001:10001 "$garments"
t0=$(date +%s)
podman "${STORE[@]}" run --rm --runtime runc --network none --read-only --tmpfs /tmp:rw,size=512m \
    --cap-drop ALL --security-opt no-new-privileges --ulimit "nofile=$(ulimit -Sn):$(ulimit -Hn)" \
    --ulimit nproc=4096:4096 \
    -v "$files:/in:ro" -v "$garments:/garments:rw" "$IMAGE" /in/skirt.obj --id wrap_skirt \
    --name "Wrap skirt" --category bottom --units cm --train-shapes 3 --test-shapes 2 --field-steps 60 \
    2>&1 | grep -v -e "it/s" -e "body/s" -e "step/s"
echo "run: import in $(($(date +%s) - t0)) s"
# A file too coarse for the drape is remeshed by pymeshlab: check that it loads and runs in the image
# (read-only root, no network), on the same file's first stage only.
"$PYTHON" -m tests.garment_files "$files/coarse" --edge 0.06 --units cm >/dev/null
podman "${STORE[@]}" run --rm --runtime runc --network none --read-only --tmpfs /tmp:rw,size=512m \
    --cap-drop ALL --security-opt no-new-privileges --ulimit "nofile=$(ulimit -Sn):$(ulimit -Hn)" \
    --ulimit nproc=4096:4096 -v "$files:/in:ro" --entrypoint python3 "$IMAGE" -c '
from pathlib import Path
from service.pipeline.body import BodyModel
from training.garment_import.pipeline import GarmentSpec, prepare
garment, notes = prepare(Path("/in/coarse/skirt.obj"), GarmentSpec("c", "C", "bottom", 3, "cm"), BodyModel.load())
print("run: coarse file:", [n for n in notes if "remeshed" in n][0])'
"$PYTHON" - "$garments" <<'PY'
import sys
from service.pipeline.catalog import verified_imports
good, bad = verified_imports(sys.argv[1])
assert [d.name for d in good] == ["wrap_skirt"] and not bad, (good, bad)
print(f"run: published {good[0]}, files match its manifest")
PY
