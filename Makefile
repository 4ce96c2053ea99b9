# Both targets run the whole idempotent set-up first (scripts/setup.sh), then their job.
SHELL := /bin/bash
.DEFAULT_GOAL := help
ENV := source scripts/env.sh

.PHONY: help setup demo test test-fast test-continual lint bench faults soak

help:
	@echo 'make demo   set up, then run the live demo'
	@echo 'make test   set up, then run the test suite'
	@echo 'make test-fast  set up, then only the pure tests (no ROS, no episodes, no training; under a minute)'
	@echo 'make lint   ruff and mypy over the project'
	@echo 'make bench  set up, then run the benchmarks (prints numbers)'
	@echo 'make faults set up, then run the whole fault matrix (test/faults; make test skips its long rows)'
	@echo 'make soak   set up, then run the three-node loop for an hour (RSS growth, step gaps)'
	@echo 'make test-continual  the live continual runs (tiny budget, also in make test; and the defaults, 3-7 min)'

setup:
	@bash scripts/setup.sh

demo: setup
	@$(ENV) && python -m zeus_ros.cli demo $(DEMO_ARGS)

# --durations: the 20 slowest tests close every run, so the suite's cost stays visible.
# Two phases. First, three pytest-xdist workers on the two cores, one test file each at a time:
# most tests wait on ROS processes rather than compute (ROS systems run side by side, each on
# its own domain id; `ros_quiet` tests keep the ROS graph to themselves: test/conftest.py).
# Same commit, idle 2-core machine: this phase took 793 s in one process, 453 s on two
# workers, 394 s on three. Then the `alone` tests (timing-sensitive, or using both cores) in one
# process (265 s): run among the others, each first waited for the other workers' current
# tests to end, and they for it. A phase that selects no test (exit 5, e.g. PYTEST_ARGS naming one
# file) is not a failure unless both select none.
# TEST_WORKERS=0 runs the first phase in one process too.
TEST_WORKERS ?= 3
PYTEST := python -m pytest -q --durations=20
test: setup
	@$(ENV) && ruff check . && mypy && \
	{ $(PYTEST) -n $(TEST_WORKERS) --dist loadfile -m 'not faults_only and not alone' $(PYTEST_ARGS); shared=$$?; \
	  $(PYTEST) -m 'alone and not faults_only' $(PYTEST_ARGS); alone=$$?; \
	  [ $$shared -eq 5 ] && [ $$alone -eq 5 ] && exit 5; \
	  for rc in $$shared $$alone; do [ $$rc -eq 0 ] || [ $$rc -eq 5 ] || exit $$rc; done; }

# The fast lane: pytest --fast (test/conftest.py) leaves out the ros, slow, faults_only and
# continual_live tests and names any test of the lane that took over 2 s.
test-fast: setup
	@$(ENV) && python -m pytest -q --fast $(PYTEST_ARGS)

lint: setup
	@$(ENV) && ruff check . && mypy

bench: setup
	@$(ENV) && for b in benchmarks/bench_*.py; do echo "== $$b"; python "$$b" || exit 1; done

test-continual: setup
	@$(ENV) && python -m pytest -q -m continual_live test/test_continual_live.py $(PYTEST_ARGS)

faults: setup
	@$(ENV) && python -m pytest -q test/faults $(PYTEST_ARGS)

soak: setup
	@$(ENV) && python benchmarks/soak.py $(SOAK_ARGS)
