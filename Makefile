# One-command set-up: `make demo` and `make test` create .venv, install the project and run.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
KERNELS := $(VENV)/.kernels
# the scenes whose runs compile every kernel the demo and the tests use (engine/warm.py), dearest first (cold
# compile on the 2-core VM: water 73-93 s, smoke 48-81 s, grass 15, energy wave 13, dust devil 3-9); the demo,
# which uses every effect, last: it then loads what the others compiled (beside the water it took 41 s, last 7-11)
WARM_SCENES := $(addprefix configs/scenes/,water_surface_showcase.toml toon_smoke_showcase.toml \
	grass_field_showcase.toml energy_wave_showcase.toml dust_devil_showcase.toml demo.toml)

.PHONY: demo test bench setup gl-deps clean

setup: $(STAMP) gl-deps $(KERNELS)

$(STAMP): pyproject.toml
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[dev,bench]"
	@touch $(STAMP)

# The effects' compiled kernels, ahead of the first run and on every core (numba caches them beside the sources):
# about a minute and a half on a fresh 2-core machine, seconds afterwards; again after a source changes.
$(KERNELS): $(STAMP) $(wildcard engine/*.py systems/*/*.py) | gl-deps
	$(PY) -m engine warm $(WARM_SCENES) && touch $@ || echo "kernel warm-up incomplete: kernels compile on first use"

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
