# Two commands from a fresh clone: `make serve` and `make test` (what .ci/run runs).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
PIP := $(BIN)/python -m pip
# -q keeps pip to warnings and errors; the version check only adds noise.
PIP_INSTALL := PIP_DISABLE_PIP_VERSION_CHECK=1 $(PIP) install -q
# The one torch pin lives in pyproject.toml; installed on its own first so that the local CPU
# wheel (pip find-links) is what satisfies anny's torch requirement, not the CUDA build.
TORCH_PIN := $(shell grep -o '"torch==[^"]*"' pyproject.toml | head -n 1 | tr -d '"')

JS_DIR := tests/js

.PHONY: serve test lint models pictures clean distclean chromium nginx

serve: $(VENV)/.installed-serve
	$(BIN)/ulnef serve

test: $(VENV)/.installed-test $(JS_DIR)/node_modules/.installed chromium nginx
	$(BIN)/ruff check .
	$(BIN)/pytest

# Rebuild every committed model from scratch (body basis, garment catalog, drape datasets of real adults
# and of the box, explicit garment models, untangling operator, neural fields), then the manifest. Each
# network is trained by training.X into a checkpoint and written to ONNX by export.X (export reads
# training, never the other way). Every long step resumes where it stopped (data/drapes*, build/*.ckpt,
# build/fields); delete them to redo.
models: $(VENV)/.installed-test
	$(BIN)/python -m export.body
	$(BIN)/python -m training.body_priors
	$(BIN)/python -m training.body_table
	$(BIN)/python -m export.body_sdf
	$(BIN)/python -m training.garments
	$(BIN)/python -m training.drape
	$(BIN)/python -m training.drape --source box --train 14 --test 8 --out data/drapes_box
	$(BIN)/python -m training.explicit --box-data data/drapes_box
	$(BIN)/python -m export.explicit
	$(BIN)/python -m training.garments.grading
	$(BIN)/python -m training.drape.sizes
	$(BIN)/python -m training.explicit_sizes
	$(BIN)/python -m training.untangler
	$(BIN)/python -m export.untangler
	$(BIN)/python -m training.fields
	$(BIN)/python -m export.fields
	$(BIN)/python -m export.manifest

pictures: $(VENV)/.installed-test
	$(BIN)/python -m training.pictures
	$(BIN)/python -m training.drape.pictures
	$(BIN)/python -m training.fields.pictures
	$(BIN)/python -m training.outfit_pictures
	$(BIN)/python -m training.collision_pictures
	$(BIN)/python -m training.measurement_pictures
	$(BIN)/python -m training.population_pictures
	$(BIN)/python -m training.self_contact_pictures

lint: $(VENV)/.installed-dev
	$(BIN)/ruff check .

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

# Stamps: reinstall only when pyproject.toml changes; a failed install leaves no stamp.
$(VENV)/.installed-serve: pyproject.toml | $(BIN)/python
	$(PIP_INSTALL) -e '.[serve]'
	touch $@

$(VENV)/.installed-dev: pyproject.toml | $(BIN)/python
	$(PIP_INSTALL) -e '.[dev]'
	touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	@test -n "$(TORCH_PIN)" || { echo "no torch==X pin found in pyproject.toml" >&2; exit 1; }
	$(PIP_INSTALL) '$(TORCH_PIN)'
	$(PIP_INSTALL) -e '.[serve,train,dev]'
	touch $@ $(VENV)/.installed-serve $(VENV)/.installed-dev

# Node tools for the glTF-validator and page tests (pinned in tests/js/package-lock.json), and
# Debian's chromium for the page test (installed only as root and only when missing). Without
# them those tests skip on a developer machine and fail in CI (CI=true).
$(JS_DIR)/node_modules/.installed: $(JS_DIR)/package.json $(JS_DIR)/package-lock.json
	@if command -v npm >/dev/null; then \
		cd $(JS_DIR) && npm ci --no-audit --no-fund --loglevel=error && touch node_modules/.installed; \
	else echo "npm not found: the glTF-validator and page tests will skip" >&2; fi

chromium:
	@command -v chromium >/dev/null || [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null || \
		{ apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; } || \
		echo "apt-get could not install chromium" >&2
	@command -v chromium >/dev/null || echo "chromium not found (Debian: apt-get install chromium): the page test will skip" >&2

# Debian's nginx for the two-replica proxy test (tests/deploy/test_proxy.py), the same way: only as
# root and only when missing. It lives in /usr/sbin, which a non-root PATH may lack.
nginx:
	@{ command -v nginx || [ -x /usr/sbin/nginx ]; } >/dev/null || [ "$$(id -u)" != 0 ] || \
		! command -v apt-get >/dev/null || \
		{ apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq nginx >/dev/null; } || \
		echo "apt-get could not install nginx" >&2
	@{ command -v nginx || [ -x /usr/sbin/nginx ]; } >/dev/null || \
		echo "nginx not found (Debian: apt-get install nginx): the proxy test will skip" >&2

clean:
	rm -rf build dist *.egg-info .pytest_cache .ruff_cache
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV)
