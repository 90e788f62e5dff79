# Two entry points for a fresh Debian 12 machine (as root): `make run` and `make test`.
# Both set everything up first; a second run only checks and is quick.

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test system venv bench lint clean

run: system venv
	$(BIN)/rfw run

test: system venv
	$(BIN)/python -m pytest -q -n 2

system:
	@bash scripts/setup-system.sh

venv: $(STAMP)

# reinstall when the dependency pins change
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $(STAMP)

bench: system venv
	$(BIN)/python benchmarks/bench_graph.py

lint: venv
	$(BIN)/ruff check rfw passes vkext tests benchmarks scripts

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
