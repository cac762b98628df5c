# dynsens — two commands for a new user:
#   make reproduce-table1   set up, then run the paper's gradient comparison (Table 1)
#   make test               set up, then run the test suite
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: install setup test test-fast lint docs min-env test-min figures-check example reproduce-table1 figures views report bench bench-all bench-peers cases clean

INSTALLED := $(VENV)/.installed-packages

# the packages (lint and docs need no compiled kernel: CI runs them beside the warm-up)
$(INSTALLED): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	touch $(INSTALLED)

install: $(INSTALLED)

# then numba's kernels and compiled steps compiled into its cache, once, in two processes (about
# 3 min on 2 quiet cores; it prints its progress)
$(STAMP): $(INSTALLED)
	$(PY) -m dynsens.warmup --jobs 2
	touch $(STAMP)

setup: $(STAMP)

# in parallel, one worker per core (pytest-xdist); a test file's tests stay on one worker so that
# its module fixtures (shared runs) are made once
test: $(STAMP)
	$(PY) -m pytest -q -n auto --dist loadfile

# a few minutes while you work: the suite without the tests listed in tests/slow_tests.txt, checked to
# exercise every module of dynsens (each process records the modules whose functions ran,
# tests/module_coverage.py; scripts/check_module_coverage.py fails on one that none did)
FAST_RECORDS := .pytest_cache/module-coverage
test-fast: $(STAMP)
	rm -rf $(FAST_RECORDS)
	DYNSENS_MODULE_COVERAGE=$(FAST_RECORDS) $(PY) -m pytest -q -n auto --dist loadfile -m "not slow"
	$(PY) scripts/check_module_coverage.py $(FAST_RECORDS)

# ruff and mypy with the configuration in pyproject.toml, and no function of dynsens/ above
# cyclomatic complexity 30 (radon; scripts/check_complexity.py). CI runs this
LINT_STAMP := $(VENV)/.lint-installed
$(LINT_STAMP): $(INSTALLED)
	$(PY) -m pip install --quiet -e ".[lint]"
	touch $(LINT_STAMP)

lint: $(LINT_STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy
	$(PY) scripts/check_complexity.py

# the documentation site -> site/ (MkDocs; warnings are errors; CI runs this)
DOCS_STAMP := $(VENV)/.docs-installed
$(DOCS_STAMP): $(INSTALLED)
	$(PY) -m pip install --quiet -e ".[docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

# the lowest versions pyproject.toml allows, in a venv of their own (CI runs this); a subset of
# the suite: the API, closed forms, case errors, the optimizer (multi-start sampling), the
# compiled kernel against numpy, the compiled steps against the Python iteration and the
# compiled sensitivity block against the Python steps (a mechanism, a structural model, random
# blocks). Its own numba cache keeps the main environment's warm. It compiles without LLVM's
# optimization passes (NUMBA_OPT=0), for CI time: 2.5 instead of 5.5 minutes, and its compiled
# against Python tests agree bit for bit all the same (no fast-math either way: optimizing does
# not change a floating-point operation). numba then leaves a few functions uncached, which one
# pytest process does not need.
MIN_VENV ?= .venv-min
MIN_PINS := numpy==1.24.0 scipy==1.10.0 h5py==3.8.0 click==8.1.0 pyyaml==6.0.1 numba==0.60.0 \
	matplotlib==3.7.0 pytest==7.4.0
MIN_STAMP := $(MIN_VENV)/.installed
MIN_TESTS := tests/test_api.py tests/test_sdof_closed_form.py tests/test_case_errors.py tests/test_optimize.py \
	tests/test_compiled_kernel.py tests/test_compiled_step.py tests/test_structural_step.py tests/test_newmark.py \
	"tests/test_direct_step.py::test_the_compiled_block_equals_the_python_steps[tyrolean_weir]" \
	"tests/test_direct_step.py::test_the_compiled_block_equals_the_python_steps[duffing_chain]" \
	tests/test_direct_step.py::test_a_block_of_random_records_equals_the_python_steps
$(MIN_STAMP): pyproject.toml Makefile
	test -x $(MIN_VENV)/bin/python || $(PYTHON) -m venv $(MIN_VENV)
	$(MIN_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(MIN_VENV)/bin/python -m pip install --quiet $(MIN_PINS)
	$(MIN_VENV)/bin/python -m pip install --quiet --no-deps -e .
	touch $(MIN_STAMP)

min-env: $(MIN_STAMP)

test-min: $(MIN_STAMP)
	$(MIN_VENV)/bin/python -c "import numpy, scipy, h5py, click, yaml, numba; \
		print('minimum versions:', numpy.__version__, scipy.__version__, h5py.__version__, click.__version__, \
		yaml.__version__, numba.__version__)"
	NUMBA_OPT=0 NUMBA_CACHE_DIR=$(MIN_VENV)/numba-cache $(MIN_VENV)/bin/python -m pytest -q -k "not dask" $(MIN_TESTS)

example: $(STAMP)
	mkdir -p results
	$(VENV)/bin/dynsens simulate cases/sdof_step.yaml -o results/sdof_step.h5 --overwrite
	$(VENV)/bin/dynsens check-gradients cases/sdof_step.yaml -o results/sdof_step_gradients

reproduce-table1: $(STAMP)
	$(PY) scripts/reproduce_table1.py

# the figures in docs/, regenerated from the current code by the commands that make them, two at a
# time (scripts/figures.py lists them; about an hour on 2 cores, most of it the weir's virtuous
# circle and the 2,252-bar ground structure, three and one verified optimizations), and their
# probes recorded in docs/figures.json; `.venv/bin/python scripts/figures.py make --from NAME`
# resumes a run that stopped at figure NAME
figures: $(STAMP)
	$(PY) scripts/figures.py make --jobs 2

# cheap check that the figures in docs/ are current (CI runs it, a few minutes): short runs of what
# each figure shows, compared with the values recorded by `make figures`
figures-check: $(STAMP)
	$(PY) scripts/figures.py check

# the weir's animation and the tower's stress-ratio frame in the README (docs/viewing.md)
views: $(STAMP)
	$(PY) scripts/make_view_figures.py

# work-precision study of the shipped cases -> results/convergence/ (tables and plots)
report: $(STAMP)
	$(VENV)/bin/dynsens convergence cases/sdof_step.yaml --dt 0.02,0.01,0.005,0.0025,0.00125 -o results/convergence
	$(VENV)/bin/dynsens convergence cases/sdof_step.yaml --set name=sdof_step_generalized_alpha --set integrator.scheme=generalized_alpha --set integrator.rho_inf=0.6 --dt 0.02,0.01,0.005,0.0025,0.00125 --methods ddm-forward,ddm-complex -o results/convergence
	$(VENV)/bin/dynsens convergence cases/sdof_step.yaml --set name=sdof_step_gamma_0.6 --set integrator.gamma=0.6 --set integrator.beta=0.3025 --dt 0.02,0.01,0.005,0.0025,0.00125 --methods ddm-forward,ddm-complex -o results/convergence
	$(VENV)/bin/dynsens convergence cases/duffing_chain.yaml --set integrator.t_end=1 --dt 0.004,0.002,0.001,0.0005 -o results/convergence
	$(VENV)/bin/dynsens convergence cases/truss_impact.yaml --dt 4e-4,2e-4,1e-4,5e-5 -o results/convergence
	$(VENV)/bin/dynsens convergence cases/hydraulic_lever.yaml --dt 0.008,0.004,0.002,0.001 -o results/convergence
	$(VENV)/bin/dynsens convergence cases/tyrolean_weir.yaml --dt 0.004,0.002,0.001 --methods ddm-forward,fd-forward -o results/convergence
	$(PY) scripts/adaptive_report.py -o results/convergence   # a mechanism on adaptive steps beside fixed ones
	$(PY) scripts/extreme_report.py > results/extreme.md
	# a mechanism three ways: fixed steps of the plain index-1 form, with Baumgarte terms, with projection
	$(VENV)/bin/dynsens convergence cases/pendulum_projection.yaml --set name=pendulum_fixed_step --set model.projection.enabled=false --set integrator.t_end=2 --dt 0.01,0.005,0.0025 --methods ddm-forward,ddm-complex -o results/convergence
	$(VENV)/bin/dynsens convergence cases/pendulum_projection.yaml --set name=pendulum_baumgarte --set model.projection.enabled=false --set "model.stabilization={alpha: 10.0, beta: 10.0}" --set integrator.t_end=2 --dt 0.01,0.005,0.0025 --methods ddm-forward,ddm-complex -o results/convergence
	$(VENV)/bin/dynsens convergence cases/pendulum_projection.yaml --set integrator.t_end=2 --dt 0.01,0.005,0.0025 --methods ddm-forward,ddm-complex -o results/convergence
	$(PY) scripts/constraint_study.py > results/constraint_study.md

# issue 35's target table (scripts/bench_targets.py; BENCHMARKS.md): dynsens against its step-cost
# targets, beside a minimal numpy loop and a compiled JAX scan of the same chain, CPU medians, with
# the machine and its load (≈ 20 min on 2 busy cores; `$(PY) scripts/bench_targets.py --quick` shortens
# the four-bar and 10 000-DOF rows). JAX comes with the peers extra; without it the table says so
PEERS_STAMP := $(VENV)/.peers-installed
$(PEERS_STAMP): $(INSTALLED)
	$(PY) -m pip install --quiet -e ".[peers]" || echo "the peers extra did not install: the table's JAX columns will say so"
	touch $(PEERS_STAMP)

bench: $(STAMP) $(PEERS_STAMP)
	$(PY) scripts/bench_targets.py

# the per-topic benchmarks of BENCHMARKS.md's earlier sections (what `make bench` ran before)
bench-all: $(STAMP)
	$(PY) scripts/bench_versions.py . . cases/slider_crank.yaml cases/four_bar.yaml cases/hydraulic_lever.yaml cases/pendulum_3d.yaml cases/tyrolean_weir.yaml --repeats 3 --before-env DYNSENS_KERNEL=numpy
	$(PY) scripts/bench_sensitivity_cost.py --repeats 3 --no-fd --partials case cases/tyrolean_weir.yaml cases/slider_crank.yaml cases/hydraulic_lever.yaml cases/four_bar.yaml
	$(PY) scripts/bench_sensitivity_cost.py --repeats 3 --no-fd --partials complex cases/tyrolean_weir.yaml
	$(PY) scripts/bench_sensitivity_cost.py --repeats 5 cases/duffing_chain.yaml cases/sdof_step.yaml cases/truss_impact.yaml
	$(PY) scripts/bench_large.py
	$(PY) scripts/bench_step_cost.py --repeats 5

bench-peers: $(STAMP) $(PEERS_STAMP)
	$(PY) scripts/bench_peers.py

cases: $(STAMP)
	$(PY) scripts/make_cases.py

clean:
	rm -rf $(VENV) $(MIN_VENV) results .pytest_cache
