# One-command entry points. Everything installs into .venv/ at the repository
# root; nothing needs root. See README.md.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.setup-stamp
PYTEST_ARGS ?=
# make test / test-fast run the tests in worker processes, one per core (pytest-xdist). A worker gets whole test
# files (loadfile: module fixtures and module-level caches are made once), in collection order
# (--no-loadscope-reorder; xdist would otherwise hand out the files with the most tests first, the quick unit
# files, and leave the long test/integration files for the end). PYTEST_XDIST= (empty) runs the tests in this
# process, as a bare `pytest` or a single test (`.venv/bin/python -m pytest test/unit/test_x.py`) does.
PYTEST_XDIST ?= -n auto --dist loadfile --no-loadscope-reorder

.PHONY: setup demo test test-fast test-extended test-services lint bags benchmarks clean

setup: $(STAMP)

# Each step's output goes to $(SETUP_LOG); the terminal gets one line per step (a bar on a TTY) and
# the log's last lines when a step fails.
SETUP_LOG := $(VENV)/setup.log
STEP = $(PYTHON) tools/setup_step.py $(SETUP_LOG)
PIP := $(VPY) -m pip install --disable-pip-version-check --progress-bar off
PINNED := $(shell grep -c '==' constraints.txt)

$(STAMP): requirements.txt constraints.txt setup.py setup.cfg package.xml tools/build_msgs.sh $(wildcard msg_defs/msg/*.msg) $(wildcard msg_defs/srv/*.srv) msg_defs/CMakeLists.txt msg_defs/package.xml
	@echo "setup: into $(VENV) (first run a few minutes; details in $(SETUP_LOG))"
	@test -x $(VPY) || $(STEP) "creating the virtual environment" -- $(PYTHON) -m venv $(VENV)
	@$(STEP) "updating pip and setuptools" -- $(PIP) --upgrade "pip>=24" "setuptools>=69,<80" wheel
	@$(STEP) "installing $(PINNED) pinned packages" --total $(PINNED) -- $(PIP) -r requirements.txt -c constraints.txt
	@$(STEP) "building the interface package msg_defs" -- bash tools/build_msgs.sh $(VENV)
	@$(STEP) "installing battery_predictor (editable)" -- $(PIP) --no-deps --no-build-isolation -e .
	@touch $(STAMP)
	@echo "setup: ok ($(VENV))"

demo: setup
	$(VENV)/bin/battery-predictor demo

# The fleet test (test/integration/test_fleet_postgres.py) starts a PostgreSQL server of its own. As root
# with apt-get (CI on Debian), install the server package when it is missing; otherwise, or when the
# install fails, that test is skipped with the reason and everything else runs.
POSTGRES_LOG := $(VENV)/postgres-install.log
test-services:
	@if ls /usr/lib/postgresql/*/bin/pg_ctl >/dev/null 2>&1 || command -v pg_ctl >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "test: installing Debian's postgresql for the fleet test (log: $(POSTGRES_LOG))"; \
	  { timeout 600 apt-get update && DEBIAN_FRONTEND=noninteractive timeout 900 apt-get install -y \
	    --no-install-recommends postgresql; } >$(POSTGRES_LOG) 2>&1 \
	    || echo "test: postgresql could not be installed (see $(POSTGRES_LOG)); the fleet test will be skipped"; \
	else echo "test: no PostgreSQL server binaries (apt-get install postgresql); the fleet test will be skipped"; fi

# mypy checks the ROS-free packages (pyproject.toml [tool.mypy]: everything but nodes/).
test: setup test-services
	$(VENV)/bin/ruff check battery_predictor test benchmarks
	$(VPY) -m mypy
	$(VPY) -m pytest $(PYTEST_XDIST) $(PYTEST_ARGS)

# The inner loop: ruff, mypy and the ROS-free unit tests (solver-heavy tests belong in test/integration).
# `make test` stays the full suite CI runs.
test-fast: setup
	$(VENV)/bin/ruff check battery_predictor test benchmarks
	$(VPY) -m mypy
	$(VPY) -m pytest $(PYTEST_XDIST) test/unit $(PYTEST_ARGS)

# The checks marked `extended` (held-out, too slow for make test's 30 min on 2 cores), and only them.
test-extended: setup
	$(VPY) -m pytest $(PYTEST_XDIST) --extended -m extended $(PYTEST_ARGS)

lint: setup
	$(VENV)/bin/ruff check battery_predictor test benchmarks
	$(VPY) -m mypy

bags: setup
	$(VENV)/bin/battery-predictor lab make-bags --out bags

benchmarks: setup
	$(VPY) benchmarks/fit_speed.py

clean:
	rm -rf $(VENV) msg_defs/build build *.egg-info
