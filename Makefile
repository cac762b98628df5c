# dynsens — two commands for a new user:
#   make reproduce-table1   set up, then run the paper's gradient comparison (Table 1)
#   make test               set up, then run the test suite
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup test example reproduce-table1 bench cases clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test]"
	touch $(STAMP)

setup: $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q

example: $(STAMP)
	mkdir -p results
	$(VENV)/bin/dynsens simulate cases/sdof_step.yaml -o results/sdof_step.h5 --overwrite
	$(VENV)/bin/dynsens check-gradients cases/sdof_step.yaml -o results/sdof_step_gradients

reproduce-table1: $(STAMP)
	$(PY) scripts/reproduce_table1.py

bench: $(STAMP)
	$(PY) scripts/bench_sensitivity_cost.py

cases: $(STAMP)
	$(PY) scripts/make_cases.py

clean:
	rm -rf $(VENV) results .pytest_cache
