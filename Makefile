# torchratslam: every target sets itself up on a fresh clone.
PY      ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed
TORCH   := torch==2.13.0
OUT     ?= out

.PHONY: all install demo test bench lint format clean docs notebooks fuzz

all: test

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# Torch first (the pinned CPU build), then the project and its dev extras.
$(STAMP): $(BIN)/python pyproject.toml graph/pyproject.toml
	$(BIN)/python -m pip install --quiet $(TORCH)
	$(BIN)/python -m pip install --quiet -e ./graph -e ".[dev]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/python -m torchratslam.experiments.demo --out $(OUT)

test: $(STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider

# Every parser fuzzed with 5000+ random examples (make test runs a fixed, smaller set).
fuzz: $(STAMP)
	TORCHRATSLAM_FUZZ_PROFILE=fuzz $(BIN)/python -m pytest -q -p no:cacheprovider tests/torchratslam/test_fuzz.py

# OpenRatSLAM's C++ for the side-by-side table: make bench OPENRATSLAM_BUILD=/path/to/build
# (the folder holding ratslam_driver; default: build/openratslam if it exists)
export OPENRATSLAM_BUILD

bench: $(STAMP)
	$(BIN)/python -m benchmarks

# The documentation site (mkdocs, strict: any broken reference fails) into $(OUT)/site.
docs: $(STAMP)
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
