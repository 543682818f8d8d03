# Set-up and the two commands of the README.  Everything lives in a local .venv.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python

.PHONY: demo test bench clean extension

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $@

demo: $(VENV)/.installed
	$(PY) -m engine render examples/demo.json -o out/demo.exr

# Test files are shared out whole to TEST_WORKERS processes (module fixtures are built once);
# TEST_WORKERS=0 runs everything in this process.
TEST_WORKERS ?= 2

test: $(VENV)/.installed
	$(PY) -m ruff check .
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadfile

bench: $(VENV)/.installed
	$(PY) tests/bench/bench_engine.py

clean:
	rm -rf out build dist *.egg-info

# One zip per platform, dist/polar_render-<version>-<platform>.zip, each with its numba, llvmlite,
# embreex and OpenEXR wheels (downloaded into wheels/ with pip: needs network at build time only).
extension: $(VENV)/.installed
	$(PY) -m polar_addon.packaging --output-dir dist
