# One-command set-up: `make demo` and `make test` create .venv, install the project and run.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

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
	$(PY) -m game_demo $(DEMO_ARGS)

test: setup
	$(PY) -m engine validate configs/
	$(PY) -m pytest

bench: setup
	@for f in bench/*_bench.py; do echo "== $$f"; $(PY) $$f || exit 1; done

clean:
	rm -rf $(VENV) out .pytest_cache
