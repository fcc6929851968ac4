# The README's commands: `make report` and `make test`. Both install into .venv if needed.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
CONFIG ?= configs/demo.yaml
OUT    ?=
PYTEST_ARGS ?=

.PHONY: install report diagnose test bench clean

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

bench: $(STAMP)
	@$(BIN)/python -m pipeline.bench

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
