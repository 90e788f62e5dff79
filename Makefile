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
	$(BIN)/python -m pytest -q -n 2 --durations=25

system:
	@bash scripts/setup-system.sh

venv: $(STAMP)

# reinstall when the dependency pins change
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $(STAMP)

# the full benchmark matrix with peers -> out/bench/report.md (tens of minutes on lavapipe)
BENCH_OUT ?= out/bench
BENCH_SIZE ?= 1280x720
BENCH_FRAMES ?= 30
BENCH_REPEAT ?= 5
BENCH_ARGS ?=
PEERS_STAMP := $(VENV)/.peers

bench: system venv $(PEERS_STAMP)
	$(BIN)/rfw bench deferred deferred@vk forward deferred_ssao_shadows meshlet@vk flat flat@vk \
	  --vary ao=on,off --size $(BENCH_SIZE) --frames $(BENCH_FRAMES) --warmup 3 \
	  --repeat $(BENCH_REPEAT) --peers all --peer-frames 10 --out $(BENCH_OUT) $(BENCH_ARGS)
	$(BIN)/python benchmarks/bench_graph.py --out $(BENCH_OUT)/bench_graph.jsonl

# peer renderers (moderngl, pygfx, open3d, mitsuba, embreex); open3d needs libusb (system)
$(PEERS_STAMP): pyproject.toml $(STAMP)
	$(BIN)/python -m pip install -q -e '.[test,peers]'
	touch $(PEERS_STAMP)

lint: venv
	$(BIN)/ruff check rfw passes vkext tests benchmarks scripts

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
