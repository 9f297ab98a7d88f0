# The two commands of the README: `make run` and `make test`. Both create .venv when it is
# missing and (re)install the project with its test extras when pyproject.toml changes.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

.PHONY: run test test-fast lint install bench bench-service clean

$(PY):
	$(PYTHON) -m venv $(VENV)

$(STAMP): pyproject.toml | $(PY)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

# The service on http://127.0.0.1:8000 (dashboard at /, API docs at /docs); the example scenes
# are served by GET /scenes/examples; jobs are kept in ctp-jobs.db (CTP_DATABASE_URL to change).
run: install
	$(VENV)/bin/uvicorn api.main:app --host 127.0.0.1 --port 8000

lint: install
	$(PY) -m ruff check analysis planner sim api ctp tests benchmarks examples
	$(PY) -m mypy

# The whole suite, slow tests included (CI runs exactly this).
test: lint
	$(PY) -m pytest

test-fast: install
	$(PY) -m pytest -m "not slow"

bench: install
	$(PY) benchmarks/analysis.py

bench-service: install
	$(PY) benchmarks/service.py

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache *.egg-info
