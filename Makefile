# Two entry points for a fresh machine:  `make repro` (tiny end-to-end reproduction) and `make test`.
SHELL := /bin/bash
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl

.PHONY: setup sysdeps browser repro lint test test-fast test-device-script bench clean

# Debian rendering packages (Mesa EGL); skipped when already present or when not root.
sysdeps:
	@if ! ldconfig -p | grep -q 'libEGL.so.1' || [ ! -e /usr/lib/x86_64-linux-gnu/dri ] && [ ! -e /usr/lib/aarch64-linux-gnu/dri ]; then \
	  if [ "$$(id -u)" = 0 ]; then apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libegl1 libgl1-mesa-dri libglvnd0 >/dev/null; \
	  else echo "missing libegl1/libgl1-mesa-dri: install them (apt-get install libegl1 libgl1-mesa-dri)"; fi; fi

# Headless Chromium for the report's HTML tests (tests/browser.py: REPORT.html opened alone, a screenshot read back;
# skipped without it): Debian's chromium-headless-shell, installed when missing and root; never fails the build.
browser:
	@command -v chromium-headless-shell >/dev/null || command -v chromium >/dev/null || \
	  if [ "$$(id -u)" = 0 ]; then (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	    chromium-headless-shell >/dev/null) || echo "chromium-headless-shell not installed: the browser tests skip"; \
	  else echo "no headless Chromium (apt-get install chromium-headless-shell): the browser tests skip"; fi

$(STAMP): requirements.txt pyproject.toml
	$(MAKE) sysdeps
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q torch==2.13.0
	$(BIN)/pip install -q -r requirements.txt
	$(BIN)/pip install -q --no-deps -e .
	touch $(STAMP)

setup: $(STAMP)

# The optional W&B mirror (runtime.wandb, pyproject's [wandb] extra): lint and the tests install it, so CI checks
# the mirror for real; `make repro` does not need it.
WANDB_STAMP := $(VENV)/.installed-wandb
$(WANDB_STAMP): $(STAMP)
	$(BIN)/pip install -q -e '.[wandb]'
	touch $(WANDB_STAMP)

# The worked example of docs/extending.md, a plugin package installed as a user would: tests/test_plugins.py trains
# its learner and objective through the entry points it registers.
PLUGIN_STAMP := $(VENV)/.installed-plugin-example
$(PLUGIN_STAMP): $(STAMP) tests/plugin_example/pyproject.toml
	$(BIN)/pip install -q --no-deps -e tests/plugin_example
	touch $(PLUGIN_STAMP)

# The main job: a tiny end-to-end reproduction on the defaults.
repro: $(STAMP)
	$(BIN)/repro reproduce

# Static checks on the packages (ruff: pyproject [tool.ruff]; mypy: pyproject [tool.mypy]).
lint: $(STAMP) $(WANDB_STAMP) $(PLUGIN_STAMP)
	$(BIN)/ruff check repro repro_data analysis paper_figures repro_app tests benchmarks
	$(BIN)/mypy

# Two pytest workers (this project's CI machine has 2 cores); the tests sharing one session run (tests/conftest.py)
# are kept on one worker (--dist loadgroup), and the longest units are queued first (tests/conftest.py). The 15
# slowest are printed so they stay visible.
XDIST ?= -n 2 --dist loadgroup
# benchmarks/gpu_check.sh's own CPU run (the device_script mark, about 2 minutes) is left to `make test-device-script`,
# so that the suite stays within CI's 12 minutes; the launcher's GPU placement and the e2e bench are tested here.
test: lint browser
	$(BIN)/python -m pytest -q -ra $(XDIST) --durations=15 -m "not device_script" $(PYTEST_ARGS)

test-device-script: $(STAMP) $(WANDB_STAMP) $(PLUGIN_STAMP)
	$(BIN)/python -m pytest -q -ra -m device_script $(PYTEST_ARGS)

# The inner loop: unit tests only (no end-to-end runs, no SLURM), a few minutes.
test-fast: $(STAMP) $(WANDB_STAMP) $(PLUGIN_STAMP) browser
	$(BIN)/python -m pytest -q -ra $(XDIST) -m "not slow and not slurm" $(PYTEST_ARGS)

bench: $(STAMP)
	$(BIN)/repro bench update

clean:
	rm -rf $(VENV) runs results
