# Everything the project needs is installed by these targets from a machine that has only
# Python 3.11 and pip.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin

# Python keeps the modules it compiles, and pytest the test modules it rewrites, in
# __pycache__ (ignored by git). Where PYTHONDONTWRITEBYTECODE is set, every test worker and
# every process a test starts (Dask workers, gcs, the mock) would compile gcs and the tests
# again: make's commands run without it (docs/testing.md)
unexport PYTHONDONTWRITEBYTECODE

.PHONY: setup test test-flights test-quick test-fast test-other-cpu test-px4 test-lab-floor fly fly-mocap lint bench clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@

PYTEST  := $(BIN)/python -m pytest -n 2 --dist worksteal -q
FAST    := -m "not e2e and not px4 and not live and not processes"
FLIGHTS := -m "e2e or px4 or live or processes"
# what test-other-cpu takes of NUMERIC_TESTS: all but the flights, Dask's clusters included
NUMERIC := -m "not e2e and not px4 and not live"
# a real-time flight keeps about 0.3-0.4 of a core busy (its vehicle, gcs, MAVSDK's server) and
# spends the rest waiting on the clock: four at once leave the quick tests (at nice 10) the rest
# of two cores, and both parts end at about the same time (docs/testing.md)
FLIGHT_WORKERS ?= 4
# pytest runs a worker per core, and OpenBLAS (numpy's copy and scipy's) starts a thread per
# core in each: on 2 cores, four BLAS threads spinning against each other. The tests that run in
# their own process get one BLAS thread per worker unless OPENBLAS_NUM_THREADS says otherwise
# (measured on 2 quiet cores: make test-fast 126-134 s with the default, 80-82 s with one;
# docs/testing.md). The flights keep the default: the processes they start run as a user's do
test-fast test-quick test-other-cpu: export OPENBLAS_NUM_THREADS ?= 1
# the tests that compare numbers with records made on another machine (tests/records.py), and
# those that hold a result bit for bit on one machine (workers vs one process, resumed vs not,
# kept learner vs new): run again as on another CPU by test-other-cpu
NUMERIC_TESTS := tests/test_trajectory_regression.py tests/test_learning_regression.py \
	tests/test_montecarlo_dask.py tests/test_mock_estimator.py tests/test_mock_vertical.py \
	tests/test_learner.py tests/test_update.py tests/test_estimators.py tests/test_model.py \
	tests/test_study.py tests/test_montecarlo.py

# the whole suite, then the numerical tests as on another CPU. The real-firmware tests
# (tests/px4/) are part of it whenever a PX4 SITL build is there (PX4_SITL_DIR, or the default
# in tests/px4/sitl.py; docs/px4-sitl.md). Two parts run at once, each part's output printed
# whole when it ends: the real-time flights, and the quick tests at a lower CPU priority
# (nice), so that they take only the cores the flights leave idle and never delay a flight's
# streams (docs/testing.md)
test: setup
	$(MAKE) --no-print-directory -j2 --output-sync=target test-flights test-quick

# the real-time flights and servers, the real firmware, and the tests that start Dask clusters
# or install the wheel (at a normal priority: the flights' threads are real-time)
test-flights: setup
	$(BIN)/python -m pytest -n $(FLIGHT_WORKERS) --dist worksteal -q $(FLIGHTS)

# test-fast, then test-other-cpu, both at a lower CPU priority. Hypothesis draws its examples
# from a fixed seed here, so that make test judges the same examples every run; make test-fast
# draws new ones each run (docs/testing.md)
HYPOTHESIS_SEED ?= 0
test-quick: setup
	nice -n 10 $(PYTEST) $(FAST) --hypothesis-seed=$(HYPOTHESIS_SEED)
	nice -n 10 $(MAKE) --no-print-directory test-other-cpu PYTEST="$(PYTEST) --hypothesis-seed=$(HYPOTHESIS_SEED)"

# everything but the real-time flights and servers, the real firmware, and the tests that start
# Dask clusters or install the wheel: the tests that run in their own process
test-fast: setup
	$(PYTEST) $(FAST)

# numpy without its SIMD dispatch and OpenBLAS on another kernel (tools/other_cpu.py checks that
# both changed, or fails): the records of tests/data must hold there too (docs/results.md)
test-other-cpu: setup
	$(BIN)/python tools/other_cpu.py $(PYTEST) $(NUMERIC) $(NUMERIC_TESTS)

# the real-firmware tests alone
test-px4: setup
	$(BIN)/python -m pytest -n 2 --dist worksteal -q -m "px4 and not lab_floor" tests/px4

# learning at the floor on real firmware in a lab as real ones are: one flight of about five
# minutes whose bound is statistical (part of make test too; docs/testing.md)
test-lab-floor: setup
	$(BIN)/python -m pytest -q -m lab_floor tests/px4

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
