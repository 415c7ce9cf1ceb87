# torchratslam: every target sets itself up on a fresh clone.
PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed
TORCH   := torch==2.13.0
OUT     ?= out

.PHONY: all install demo test test-extras bench lint format clean docs notebooks fuzz

all: test

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# Torch first (the pinned CPU build), then the project (both packages, torchratslam and
# ratslam_graph) and its dev extras (what the tests need; the tests of an optional extra
# skip, naming it, when it is absent).
$(STAMP): $(BIN)/python pyproject.toml graph/pyproject.toml
	$(BIN)/python -m pip install --quiet $(TORCH)
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

# One optional extra (docs, viewer, tune, ray, parquet, gym, evo, all) on top of dev.
$(VENV)/.extra-%: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[dev,$*]"
	touch $@

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/python -m torchratslam.experiments.demo --out $(OUT)

# Both cores (pytest-xdist; a test module's fixtures stay on one worker).
test: $(STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider -n 2 --dist loadfile

# The tests that need an optional extra (rerun, Ray, Optuna, Parquet, Gymnasium, evo, mkdocs).
test-extras: $(VENV)/.extra-all
	$(BIN)/python -m pytest -q -p no:cacheprovider tests/test_docs.py \
	  tests/torchratslam/viz/test_rerun_viewer.py tests/torchratslam/sweeps \
	  tests/torchratslam/sim/office/test_env.py tests/torchratslam/eval/test_tum.py

# Every parser fuzzed with 5000+ random examples (make test runs the corpus of inputs that
# once failed, tests/data/fuzz_corpus/, and a few hundred new random examples per parser).
fuzz: $(STAMP)
	TORCHRATSLAM_FUZZ_PROFILE=fuzz $(BIN)/python -m pytest -q -p no:cacheprovider tests/torchratslam/test_fuzz.py

# The speed report side by side with OpenRatSLAM's C++: make bench OPENRATSLAM_BUILD=/path/to/build
# (the folder holding ratslam_driver; default: build/openratslam if it exists).
# BENCH_ARGS: --quick (fewer frames), --profile (per stage), --only NAMES, --all.
export OPENRATSLAM_BUILD
BENCH_ARGS ?=

bench: $(STAMP)
	$(BIN)/python -m benchmarks $(BENCH_ARGS)

# The documentation site (mkdocs, strict: any broken reference fails) into $(OUT)/site.
docs: $(VENV)/.extra-docs
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir $(OUT)/site

# Execute every notebook in place (outputs kept, volatile metadata stripped).
notebooks: $(STAMP)
	$(BIN)/python notebooks/execute.py

# ruff, mypy and the import contracts ([tool.importlinter]); each must report nothing.
lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy -p torchratslam -p ratslam_graph
	PYTHONPATH=graph:. $(BIN)/lint-imports --no-cache

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

clean:
	rm -rf $(OUT) build *.egg-info .pytest_cache
