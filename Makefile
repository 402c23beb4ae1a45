# The two commands of the README: `make demo` (the main job) and `make test` (the test suite).
# Each creates .venv/ on first use and installs the project with its dev extras.

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# The CUDA builds of this pair import and run on a CPU-only machine; the CPU torch wheel has
# no matching torchvision build (see README, Installation).
TORCH_PIN := torch==2.14.1 torchvision==0.29.1
DEMO_OUT  ?= out/demo

.PHONY: setup test demo bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet $(TORCH_PIN)
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -q

demo: $(STAMP)
	$(BIN)/riskmap collect --env highway-v0 --episodes 4 --seed 0 --out $(DEMO_OUT)/data/highway --workers 2 --resume
	$(BIN)/riskmap collect --env intersection-v0 --episodes 4 --seed 0 --out $(DEMO_OUT)/data/intersection --workers 2 --resume
	$(BIN)/riskmap figures scenes --data $(DEMO_OUT)/data/highway --out $(DEMO_OUT)/figures/highway --count 4
	$(BIN)/riskmap figures scenes --data $(DEMO_OUT)/data/intersection --out $(DEMO_OUT)/figures/intersection --count 4
	@echo "demo: datasets in $(DEMO_OUT)/data, figures in $(DEMO_OUT)/figures"

bench: $(STAMP)
	$(BIN)/python experiments/bench_collect.py

clean:
	rm -rf out .pytest_cache
