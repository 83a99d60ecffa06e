# Each user-facing target creates .venv and installs into it when it is missing
# or older than pyproject.toml, so `make test` and `make demo` each work on a
# fresh machine as a single command.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.dynprop-installed
DEMO_DIR ?= runs/demo-$(shell date -u +%Y%m%dT%H%M%SZ)

.PHONY: test test-vm demo bench lint docs venv clean

# The install prints no warnings.  PYTHONWARNINGS silences only setuptools' notice at
# every editable install (a folder named like the package in the working directory may
# shadow it): here that folder is the package's own source.
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	PYTHONWARNINGS='ignore:Editable installation' $(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

venv: $(STAMP)

# --durations=20: each pass ends with its 20 slowest tests, for the suite's time budget.
test: $(STAMP)
	PYTHONWARNINGS=error $(BIN)/python -m pytest --durations=20

# The suite again as on another machine: CasADi's VM in place of the compiled C, and
# numpy's matrix products on another OpenBLAS kernel (.ci/other_blas_kernel.py), so
# their last bits differ as another CPU's or compiler's would.  Tests whose requirement
# is compiled code itself are marked compiled_only and skipped.
test-vm: $(STAMP)
	@kernel=$$($(BIN)/python .ci/other_blas_kernel.py); \
	echo "second pass: CasADi VM, OpenBLAS kernel $${kernel:-unchanged}"; \
	env DYNPROP_BACKEND=vm $${kernel:+OPENBLAS_CORETYPE=$$kernel} PYTHONWARNINGS=error \
		$(BIN)/python -m pytest --durations=20

demo: $(STAMP)
	$(BIN)/dynprop run goes_next_equinox --out $(DEMO_DIR) --report

bench: $(STAMP)
	$(BIN)/python benchmarks/run.py $(BENCH)

lint: $(STAMP)
	$(BIN)/ruff check .

# docs/scenario-reference.md is generated from the schema; a test fails when it is stale.
docs: $(STAMP)
	$(BIN)/python -m dynprop.scenarios.config.reference --out docs/scenario-reference.md

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache
