# The README's two commands: `make demo` and `make test`.
# Both work on a fresh machine with only Python >= 3.11 and make.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DOCS_STAMP := $(VENV)/.docs-installed

.PHONY: demo test check install bench docs clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e '.[test,docs]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/grainforge demo --out out/demo --overwrite

# the suite runs on PYTEST_PROCS processes (pytest-xdist; the machine the targets are set on has 2 cores),
# one test at a time to whichever process is free, the slow tests first (tests/conftest.py)
PYTEST_PROCS ?= 2
PYTEST_DIST  ?= --dist load --maxschedchunk 1

test: $(STAMP)
	$(BIN)/python -m pytest -n $(PYTEST_PROCS) $(PYTEST_DIST) --durations=25

# the fast lane for everyday work: lint, then every test not marked slow
check: $(STAMP)
	$(BIN)/ruff check src tests benchmarks
	$(BIN)/python -m pytest -m "not slow" -q -n $(PYTEST_PROCS) $(PYTEST_DIST)

bench: $(STAMP)
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

$(DOCS_STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet -e '.[docs]'
	touch $(DOCS_STAMP)

# the documentation site (mkdocs.yml) into build/site; --strict: a broken link or reference fails
docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict -d build/site

clean:
	rm -rf $(VENV) out build dist src/*.egg-info .pytest_cache .hypothesis
