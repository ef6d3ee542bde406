# One-command entry points. Everything installs into .venv/ at the repository
# root; nothing needs root. See README.md.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
STAMP := $(VENV)/.setup-stamp
PYTEST_ARGS ?=

.PHONY: setup demo test lint bags benchmarks clean

setup: $(STAMP)

$(STAMP): requirements.txt constraints.txt setup.py setup.cfg package.xml tools/build_msgs.sh $(wildcard msg_defs/msg/*.msg) $(wildcard msg_defs/srv/*.srv) msg_defs/CMakeLists.txt msg_defs/package.xml
	@test -x $(VPY) || $(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install --quiet --disable-pip-version-check --upgrade "pip>=24" "setuptools>=69,<80" wheel
	$(VPY) -m pip install --quiet --disable-pip-version-check -r requirements.txt -c constraints.txt
	bash tools/build_msgs.sh $(VENV)
	$(VPY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $(STAMP)
	@echo "setup: ok ($(VENV))"

demo: setup
	$(VENV)/bin/battery-predictor demo

test: setup
	$(VENV)/bin/ruff check battery_predictor test benchmarks
	$(VPY) -m pytest $(PYTEST_ARGS)

lint: setup
	$(VENV)/bin/ruff check battery_predictor test benchmarks

bags: setup
	$(VENV)/bin/battery-predictor lab make-bags --out bags

benchmarks: setup
	$(VPY) benchmarks/fit_speed.py

clean:
	rm -rf $(VENV) msg_defs/build build *.egg-info
