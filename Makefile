# Set-up and the two commands of the README.  Everything lives in a local .venv.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python

.PHONY: demo test test-fast bench clean extension

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	@echo "Compiling the render kernels into the cache (once, a minute or two: renders then start at once)"
	$(PY) -m engine precompile || echo "warning: precompiling failed: the first render compiles its kernels"
	touch $@

demo: $(VENV)/.installed
	$(PY) -m engine render examples/demo.json -o out/demo.exr

# Test files are shared out whole to TEST_WORKERS processes (module fixtures are built once);
# TEST_WORKERS=0 runs everything in this process.
TEST_WORKERS ?= 2

# The extension's smoke set also runs on the oldest and newest supported Blender (4.5 LTS on
# Python 3.11, 5.3 on Python 3.13), each in .venv-blender/bpy-<release> (created once, ~400 MB each).
BLENDER_SERIES ?= 4.5 5.3

test: $(VENV)/.installed
	$(PY) -m ruff check .
	$(PY) tests/support/blender_envs.py $(BLENDER_SERIES)
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadfile

# The pure-engine tests while developing (under two minutes on 2 cores): no Blender, no other
# processes, no Dask cluster, no fuzzers.  Test folders: tests/{materials,kernels,render,scene,cli,blender}.
test-fast: $(VENV)/.installed
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadfile -q -m "not blender and not subprocess and not cluster and not fuzz"

bench: $(VENV)/.installed
	$(PY) tests/bench/bench_engine.py

clean:
	rm -rf out build dist *.egg-info

# One zip per platform, dist/polar_render-<version>-<platform>.zip, each with its numba, llvmlite,
# embreex and OpenEXR wheels (downloaded into wheels/ with pip: needs network at build time only).
extension: $(VENV)/.installed
	$(PY) -m polar_addon.packaging --output-dir dist
