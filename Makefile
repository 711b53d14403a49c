# Two commands do all set-up on a fresh machine:
#   make demo   create .venv, install, render the gallery into out/
#   make test   create .venv, install, run the test suite (graders, references, course)
# and one opens the lecture notebooks:
#   make lab    create .venv, install, start JupyterLab on slides/ (LAB_ARGS: its options)
# For the course's maintainers (CI runs it before the tests):
#   make lint   ruff check, ruff format --check, and labs/ as solutions/ generate it
#
# torch: on a machine without an NVIDIA GPU torch is installed first, on its own, as
# TORCH_SPEC from TORCH_INDEX (pip's own index when empty). On macOS and Windows that is
# the CPU build; on Linux PyPI's torch is the CUDA build (gigabytes of CUDA libraries), so
# a Linux machine without a GPU is best served by PyTorch's CPU index:
#   make test TORCH_INDEX=https://download.pytorch.org/whl/cpu
# PIP_EXTRA adds options to every pip command (another index, a proxy).
PYTHON ?= python3
VENV ?= .venv
TORCH_SPEC ?= torch==2.13.0
TORCH_INDEX ?=
PIP_EXTRA ?=
LAB_ARGS ?=
PY := $(VENV)/bin/python
HAS_GPU := $(shell command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1 && echo 1)
# Jupyter refuses to start as root (a container, WSL's default user) without this flag.
AS_ROOT := $(if $(filter 0,$(shell id -u 2>/dev/null)),--allow-root)

.PHONY: demo test lab lint grade release clean

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
ifneq ($(HAS_GPU),1)
	$(PY) -m pip install --quiet --disable-pip-version-check $(PIP_EXTRA) \
	    $(if $(TORCH_INDEX),--index-url $(TORCH_INDEX)) "$(TORCH_SPEC)"
endif
	$(PY) -m pip install --quiet --disable-pip-version-check $(PIP_EXTRA) -e ".[dev]"
	touch $@

demo: $(VENV)/.installed
	$(VENV)/bin/rtcourse demo

test: $(VENV)/.installed
	$(PY) -m pytest -q -rs -p no:cacheprovider

lab: $(VENV)/.installed
	$(VENV)/bin/jupyter lab $(AS_ROOT) $(LAB_ARGS) slides

lint: $(VENV)/.installed
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(if $(wildcard solutions),$(VENV)/bin/rtcourse skeletons --check)

grade: $(VENV)/.installed
	$(VENV)/bin/rtcourse grade --impl labs --json results.json

release: $(VENV)/.installed
	$(VENV)/bin/rtcourse release out/handout

clean:
	rm -rf $(VENV) out .pytest_cache
