# Two commands on a fresh machine: `make demo` (the main job) and `make test`.
# The CPU build of torch is installed first so that no dependency pulls CUDA wheels; the
# [cluster] extra (hydra-submitit-launcher, ~80 kB of pure Python) lets the tests sweep on it; the
# [minari], [tensorboard], [wandb] and [video] extras let the tests of those features run.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test install clean

# constraints.txt pins every package to the versions the results were made with (see its header).
$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -c constraints.txt torch==2.13.0
	$(PY) -m pip install -q -c constraints.txt -e '.[test,cluster,minari,tensorboard,wandb,video]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(PY) -m torchrl_causal.demo

test: $(STAMP)
	OMP_NUM_THREADS=1 $(PY) -m pytest -n auto --dist loadfile

clean:
	rm -rf $(VENV) outputs multirun .pytest_cache
