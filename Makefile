# Two commands on a fresh machine: `make demo` (the main job) and `make test`.
# The CPU build of torch is installed first so that no dependency pulls CUDA wheels; the
# [cluster] extra (hydra-submitit-launcher, ~80 kB of pure Python) lets the tests sweep on it; the
# [minari], [tensorboard], [wandb] and [video] extras let the tests of those features run; [docs]
# (Sphinx, MyST) builds the API reference: `make docs`.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test docs install clean

# constraints.txt pins every package to the versions the results were made with (see its header).
$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -c constraints.txt torch==2.13.0
	$(PY) -m pip install -q -c constraints.txt -e '.[test,cluster,minari,tensorboard,wandb,video,docs]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(PY) -m torchrl_causal.demo

test: $(STAMP)
	OMP_NUM_THREADS=1 $(PY) -m pytest -n auto --dist loadfile

# The API reference, offline, into docs/_build/html: -W -n fails the build on any warning, an
# unresolved reference to this package's objects included (docs/conf.py says which other
# libraries' names are let through: no inventory of theirs is downloaded).
docs: $(STAMP)
	rm -rf docs/_build docs/api/generated
	OMP_NUM_THREADS=1 $(PY) -m sphinx -b html -W -n --keep-going -q docs docs/_build/html
	@echo "docs: docs/_build/html/index.html"

clean:
	rm -rf $(VENV) outputs multirun .pytest_cache docs/_build docs/api/generated
