# One-command set-up: `make demo` and `make test` create .venv, install the project and run.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SCENE ?= configs/scenes/sandbox.toml

.PHONY: demo test bench setup gl-deps clean

setup: $(STAMP) gl-deps

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev,bench]"
	@touch $(STAMP)

# Headless OpenGL needs Mesa's EGL; install it when missing and we are root, else say how.
gl-deps:
	@sh tools/check_gl_deps.sh

demo: setup
	$(PY) -m engine run $(SCENE) $(DEMO_ARGS)

test: setup
	$(PY) -m engine validate configs/
	$(PY) -m pytest

bench: setup
	$(PY) bench/ecs_bench.py
	$(PY) bench/render_bench.py

clean:
	rm -rf $(VENV) out .pytest_cache
