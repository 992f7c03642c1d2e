# dockfactory: `make demo` and `make test` set up .venv by themselves (Python 3.11 + make only).
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-fast lint venv clean-demo paper

venv: $(STAMP)

$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "need $(PYTHON) on PATH (or make PYTHON=/path/to/python3.11)"; exit 1; }
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	# torch pinned to the CPU build (any other spec pulls a multi-GB CUDA build); one resolve for all
	$(BIN)/python -m pip install --quiet "torch==2.13.0" -e ".[test,ray,onnx,dvc,hf,pdf]"
	touch $(STAMP)

# render -> detect (shipped weights) -> solve -> evaluate -> report on the quick config.
# A rejected (exit 1) or not-proven (exit 3) verdict is a result, not a failure of the demo; other errors stop make.
demo: $(STAMP)
	@$(BIN)/dockfactory run configs/quick.toml --out out/quick; rc=$$?; [ $$rc -le 1 ] || [ $$rc -eq 3 ] || exit $$rc
	@$(BIN)/dockfactory show out/quick/dataset 000000 --out out/quick/overlay_000000.png >/dev/null
	@echo "report: out/quick/report.html  (summary: out/quick/report.md)"
	@echo "dataset: out/quick/dataset (images/, labels/, manifest.json); one frame with its labels: out/quick/overlay_000000.png"

# both cores (pytest-xdist), each test file on one worker (its module fixtures, a render or a
# training, made once); the 20 slowest tests listed at the end
test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --durations=20

lint: $(STAMP)
	$(BIN)/ruff check .   # the rules of [tool.ruff.lint] in pyproject.toml

# everything that neither renders nor trains for long (pyproject.toml: markers); its time on an
# idle 2-core machine: bench/results/speeds/speeds.json
test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 -m "not render and not slow"   # both cores (pytest-xdist)

# issue 13, the paper at full scale: hours of rendering and training on 2 cores, resumable
# (bench/paper/paper.sh says what each step costs); results land in results/paper/
paper: $(STAMP)
	sh bench/paper/paper.sh all

clean-demo:
	rm -rf out/quick
