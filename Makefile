# The README's commands: `make report` and `make test`. Both install into .venv if needed.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
CONFIG ?= configs/demo.yaml
OUT    ?=
PYTEST_ARGS ?=

.PHONY: install report diagnose test bench bench-diagnosis bench-two-causes clean

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	@echo "installing into $(VENV) (first run only)..."
	@$(BIN)/python -m pip install -q --disable-pip-version-check -e '.[dev]'
	@touch $(STAMP)

install: $(STAMP)

report: $(STAMP)
	@$(BIN)/python -m pipeline report $(CONFIG) $(if $(OUT),--out $(OUT),)

diagnose: $(STAMP)
	@$(BIN)/python -m pipeline diagnose $(CONFIG) $(if $(OUT),--out $(OUT),)

test: $(STAMP)
	@$(BIN)/python -m pytest -q $(PYTEST_ARGS)

# benchmarks run in their own environment: SysIdentPy (the FROLS comparison) is installed there only
BENCH_VENV := .venv-bench
$(BENCH_VENV)/.installed: pyproject.toml
	@test -x $(BENCH_VENV)/bin/python || $(PYTHON) -m venv $(BENCH_VENV)
	@echo "installing the benchmark environment into $(BENCH_VENV) (first run only)..."
	@$(BENCH_VENV)/bin/python -m pip install -q --disable-pip-version-check -e . sysidentpy
	@touch $@

bench: $(BENCH_VENV)/.installed
	@$(BENCH_VENV)/bin/python -m pipeline.bench

# the diagnosis on independent records (pipeline.bench.diagnosis); QUICK=1 for a small grid,
# SEEDS=test for the held-out seeds; writes its own section of BENCHMARKS.md
bench-diagnosis: $(STAMP)
	@$(BIN)/python -m pipeline.bench.diagnosis $(if $(QUICK),--quick,) $(if $(SEEDS),--seeds $(SEEDS),)

# two hidden causes at once, on solve_ivp records (pipeline.bench.two_causes); writes its own section
bench-two-causes: $(STAMP)
	@$(BIN)/python -m pipeline.bench.two_causes $(if $(SEEDS),--seeds $(SEEDS),)

clean:
	rm -rf $(VENV) $(BENCH_VENV) build *.egg-info .pytest_cache
