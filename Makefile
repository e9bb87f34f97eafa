# Every target does its own set-up: a local virtual environment with the package in it, and
# libLLVM >= 16 via apt when missing (Dr.Jit 1.5 aborts with LLVM 14/15). Idempotent.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.draaw-mi-installed

.PHONY: help setup llvm demo test test-all docs clean
# a bare `make` lists the targets: set-up may install libLLVM with apt (as root)
.DEFAULT_GOAL := help

help:
	@echo "make setup      .venv with the package and its dev extra; libLLVM >= 16 via apt if missing (root)"
	@echo "make demo       set up, then render scenes/cornell.toml to out/cornell.exr and out/cornell.png"
	@echo "make test       set up, then the default test suite (not the slow tests; CI runs this)"
	@echo "make test-all   set up with the notebooks and browser extras, then every test"
	@echo "make docs       set up with the docs extra, then the documentation site in docs/_build/html"
	@echo "make notebook   set up with the notebooks extra, then JupyterLab on notebooks/"
	@echo "make llvm       only the libLLVM check (and apt install when missing)"
	@echo "make clean      remove .venv, out/, docs/_build, docs/benchmarks and .pytest_cache"

setup: llvm $(STAMP)

llvm:
	@$(PYTHON) draaw_mi/_llvm.py --install

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade "pip>=23.2"
	$(BIN)/python -m pip install -q -e ".[dev]"
	@touch $(STAMP)

# Stratified samples, denoised (OIDN, installed by setup; the emitters seen directly are not
# denoised); the raw render is kept in out/cornell.exr's channels raw.R/G/B
# (benchmarks/results/demo_quality.md).
demo: setup
	$(BIN)/draaw-mi render scenes/cornell.toml -o out/cornell.exr --png out/cornell.png --denoise --sampler multijitter

test: setup
	$(BIN)/python -m pytest -m "not slow" -q

test-all: setup
	$(BIN)/python -m pip install -q -e ".[notebooks,browser]"
	$(BIN)/python -m pytest -q

DOCS_STAMP := $(VENV)/.draaw-mi-docs-installed
$(DOCS_STAMP): $(STAMP)
	$(BIN)/python -m pip install -q -e ".[docs]"
	@touch $(DOCS_STAMP)

# The documentation site (docs/): warnings are errors (-W), every cross-reference must resolve (-n).
# Notebook outputs are stored in docs/tutorials/ and the gallery in docs/_static/gallery/
# (docs/execute_notebooks.py and docs/make_gallery.py refresh them); the build renders nothing.
docs: setup $(DOCS_STAMP)
	$(BIN)/sphinx-build -W --keep-going -n -q -b html docs docs/_build/html
	@echo "docs: open docs/_build/html/index.html"

clean:
	rm -rf $(VENV) out .pytest_cache docs/_build docs/benchmarks

# JupyterLab on notebooks/ with the widgets and the denoiser installed (material_tuning.ipynb).
.PHONY: notebook
notebook: setup
	$(BIN)/python -m pip install -q -e ".[notebooks]"
	cd notebooks && ../$(BIN)/jupyter lab
