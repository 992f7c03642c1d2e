# dockfactory: `make demo` and `make test` set up .venv by themselves (Python 3.11 + make only).
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test venv clean-demo

venv: $(STAMP)

$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "need $(PYTHON) on PATH (or make PYTHON=/path/to/python3.11)"; exit 1; }
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	# torch pinned to the CPU build (any other spec pulls a multi-GB CUDA build); one resolve for all
	$(BIN)/python -m pip install --quiet "torch==2.13.0" -e ".[test,ray]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/dockfactory render configs/quick.toml --out out/quick
	$(BIN)/dockfactory show out/quick 000000 --out out/quick/overlay_000000.png
	@echo "dataset: out/quick (images/, labels/, manifest.json); overlay: out/quick/overlay_000000.png"

test: $(STAMP)
	$(BIN)/python -m pytest -q

clean-demo:
	rm -rf out/quick
