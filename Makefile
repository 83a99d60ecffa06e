# Each user-facing target creates .venv and installs into it when it is missing
# or older than pyproject.toml, so `make test` and `make demo` each work on a
# fresh machine as a single command.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.dynprop-installed
DEMO_DIR ?= runs/demo-$(shell date -u +%Y%m%dT%H%M%SZ)

.PHONY: test demo bench lint venv clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

venv: $(STAMP)

test: $(STAMP)
	PYTHONWARNINGS=error $(BIN)/python -m pytest

demo: $(STAMP)
	$(BIN)/dynprop run goes_next_equinox --out $(DEMO_DIR)

bench: $(STAMP)
	$(BIN)/python benchmarks/run.py

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache
