# Two commands from a fresh clone: `make serve` and `make test` (what .ci/run runs).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
PIP := $(BIN)/python -m pip
# -q keeps pip to warnings and errors; the version check only adds noise.
PIP_INSTALL := PIP_DISABLE_PIP_VERSION_CHECK=1 $(PIP) install -q
# The one torch pin lives in pyproject.toml; installed on its own first so that the local CPU
# wheel (pip find-links) is what satisfies anny's torch requirement, not the CUDA build.
TORCH_PIN := $(shell grep -o '"torch==[^"]*"' pyproject.toml | tr -d '"')

.PHONY: serve test lint models pictures clean distclean

serve: $(VENV)/.installed-serve
	$(BIN)/ulnef serve

test: $(VENV)/.installed-test
	$(BIN)/ruff check .
	$(BIN)/pytest

# Rebuild every committed model from scratch (body basis, garment catalog, drape dataset,
# explicit garment models, untangling operator, neural fields), then the manifest. Every long
# step resumes where it stopped (data/drapes, build/*.ckpt, build/fields); delete them to redo.
models: $(VENV)/.installed-test
	$(BIN)/python -m export.body
	$(BIN)/python -m training.garments
	$(BIN)/python -m training.drape
	$(BIN)/python -m training.explicit
	$(BIN)/python -m training.untangler
	$(BIN)/python -m training.fields
	$(BIN)/python -m export.manifest

pictures: $(VENV)/.installed-test
	$(BIN)/python -m training.pictures
	$(BIN)/python -m training.drape.pictures
	$(BIN)/python -m training.fields.pictures
	$(BIN)/python -m training.outfit_pictures

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

clean:
	rm -rf build dist *.egg-info .pytest_cache .ruff_cache
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV)
