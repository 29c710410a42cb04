# Everything the project needs is installed by these targets from a machine that has only
# Python 3.11 and pip.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin

.PHONY: setup test test-px4 fly fly-mocap lint bench clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@

# the real-firmware tests (tests/px4/) are part of it whenever a PX4 SITL build is there
# (PX4_SITL_DIR, or the default in tests/px4/sitl.py; docs/px4-sitl.md)
test: setup
	$(BIN)/python -m pytest -n 2 --dist worksteal -q

# the real-firmware tests alone
test-px4: setup
	$(BIN)/python -m pytest -n 2 --dist worksteal -q -m px4 tests/px4

fly: setup
	$(BIN)/gcs fly --mock --iter 3

fly-mocap: setup
	$(BIN)/gcs fly --mock --mocap mock --iter 3

lint: setup
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: setup
	$(BIN)/python benchmarks/learn_step.py

clean:
	rm -rf $(VENV) .pytest_cache
