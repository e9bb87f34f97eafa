# Every target does its own set-up: a local virtual environment with the package in it, and
# libLLVM >= 16 via apt when missing (Dr.Jit 1.5 aborts with LLVM 14/15). Idempotent.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.draaw-mi-installed

.PHONY: setup llvm demo test test-all clean

setup: llvm $(STAMP)

llvm:
	@$(PYTHON) draaw_mi/_llvm.py --install

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade "pip>=23.2"
	$(BIN)/python -m pip install -q -e ".[dev]"
	@touch $(STAMP)

demo: setup
	$(BIN)/draaw-mi render scenes/cornell.toml -o out/cornell.exr --png out/cornell.png

test: setup
	$(BIN)/python -m pytest -m "not slow" -q

test-all: setup
	$(BIN)/python -m pip install -q -e ".[notebooks,browser]"
	$(BIN)/python -m pytest -q

clean:
	rm -rf $(VENV) out .pytest_cache

# JupyterLab on notebooks/ with the widgets and the denoiser installed (material_tuning.ipynb).
.PHONY: notebook
notebook: setup
	$(BIN)/python -m pip install -q -e ".[notebooks]"
	cd notebooks && ../$(BIN)/jupyter lab
