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

.PHONY: setup test test-faults test-cluster test-commonroad-oldest test-commonroad-idm demo bench docs clean

setup: $(STAMP)

$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --no-cache-dir --upgrade pip
	$(BIN)/python -m pip install --quiet --no-cache-dir $(TORCH_PIN)
	$(BIN)/python -m pip install --quiet --no-cache-dir -c constraints.txt -e '.[dev,commonroad,guard,ray,docs]'
	$(BIN)/python -m pip install --quiet --no-cache-dir --no-deps 'commonroad-io==2026.1'   # see pyproject.toml
	touch $(STAMP)

test: $(STAMP)
	$(BIN)/lint-imports --no-logo
	$(BIN)/python -m pytest -q

# The longer kill-and-resume sweep: every long command killed after its first atomic write and
# at its last one too (make test kills each halfway only).
test-faults: $(STAMP)
	$(BIN)/python -m pytest -q -m faults tests/reliability

# A two-node Ray cluster on this machine; the second node is killed mid-campaign (-rP: the log
# lines naming the lost node and the retried jobs are printed).
test-cluster: $(STAMP)
	$(BIN)/python -m pytest -q -rP -m cluster tests/adversary/campaign/test_ray_cluster.py

# The CommonRoad tests (reading recordings, scenes and rasters, signals, replay, collect, the
# export round trip) under the oldest commonroad-io that pyproject.toml allows. Only that package
# differs from the main venv, so it goes into a --target folder put first on PYTHONPATH instead of
# a second venv; COMMONROAD_IO_EXPECTED makes tests/rasterize/test_commonroad_compat.py check that
# this release, not the venv's, is the one imported.
CR_OLDEST     := 2024.3
CR_OLDEST_DIR := $(VENV)/commonroad-io-$(CR_OLDEST)
CR_TESTS := tests/rasterize/test_commonroad_compat.py tests/rasterize/test_commonroad_readings.py \
	tests/rasterize/test_commonroad.py tests/rasterize/test_signals.py \
	tests/riskmap/sim/test_commonroad_replay.py tests/riskmap/data/test_collect_commonroad.py \
	tests/adversary/export/test_commonroad_export.py

$(CR_OLDEST_DIR)/.installed: $(STAMP)
	rm -rf $(CR_OLDEST_DIR)
	$(BIN)/python -m pip install --quiet --no-cache-dir --no-deps --target $(CR_OLDEST_DIR) 'commonroad-io==$(CR_OLDEST)'
	touch $@

test-commonroad-oldest: $(CR_OLDEST_DIR)/.installed
	PYTHONPATH=$(CURDIR)/$(CR_OLDEST_DIR) COMMONROAD_IO_EXPECTED=$(CR_OLDEST) $(BIN)/python -m pytest -q $(CR_TESTS)

# An outside CommonRoad planner as the ego (examples/commonroad_idm): commonroad-idm-planner needs
# commonroad-io < 2025, so it and its pinned requirements go into their own --target folder, first
# on PYTHONPATH, as for the oldest-commonroad tests above. Polygon3 builds from source (gcc).
CR_IDM_DIR := $(VENV)/commonroad-idm

$(CR_IDM_DIR)/.installed: $(STAMP) examples/commonroad_idm/requirements.txt
	rm -rf $(CR_IDM_DIR)
	$(BIN)/python -m pip install --quiet --no-cache-dir --no-deps --target $(CR_IDM_DIR) -r examples/commonroad_idm/requirements.txt
	touch $@

test-commonroad-idm: $(CR_IDM_DIR)/.installed
	PYTHONPATH=$(CURDIR)/$(CR_IDM_DIR):$(CURDIR)/examples/commonroad_idm $(BIN)/python -m pytest -q tests/examples/test_commonroad_idm.py

demo: $(STAMP)
	$(BIN)/riskmap collect --env highway-v0 --episodes 2 --seed 2000 --out $(DEMO_OUT)/data/highway --workers 2 --resume
	$(BIN)/riskmap collect --env intersection-v0 --episodes 6 --seed 2000 --out $(DEMO_OUT)/data/intersection --workers 2 --resume
	$(BIN)/riskmap figures scenes --data $(DEMO_OUT)/data/highway --out $(DEMO_OUT)/figures/scenes_highway --count 3
	$(BIN)/riskmap figures scenes --data $(DEMO_OUT)/data/intersection --out $(DEMO_OUT)/figures/scenes_intersection --count 3
	$(BIN)/riskmap figures plans --checkpoint checkpoints/riskmap_highway --data $(DEMO_OUT)/data/highway --out $(DEMO_OUT)/figures/plans_highway --count 4
	$(BIN)/riskmap figures plans --checkpoint checkpoints/riskmap_intersection --data $(DEMO_OUT)/data/intersection --out $(DEMO_OUT)/figures/plans_intersection --count 4
	$(BIN)/riskmap figures plans --checkpoint checkpoints/riskmap_st_intersection --data $(DEMO_OUT)/data/intersection --out $(DEMO_OUT)/figures/plans_intersection_spacetime --count 2
	$(BIN)/riskmap drive --checkpoint checkpoints/riskmap_highway --env highway-v0 --episodes 2 --seed 0 --out $(DEMO_OUT)/drive/highway --resume
	$(BIN)/riskmap drive --planner idm --env highway-v0 --episodes 2 --seed 0 --out $(DEMO_OUT)/drive/highway_idm --resume
	$(BIN)/riskmap drive --checkpoint checkpoints/riskmap_intersection --env intersection-v0 --episodes 2 --seed 0 --out $(DEMO_OUT)/drive/intersection --frames --resume
	$(BIN)/riskmap drive --planner idm --env intersection-v0 --episodes 2 --seed 0 --out $(DEMO_OUT)/drive/intersection_idm --resume
	$(BIN)/adversary stress-test --config experiments/campaigns/demo.yaml --out $(DEMO_OUT)/stress --workers 2 --resume
	$(BIN)/adversary report $(DEMO_OUT)/stress --out $(DEMO_OUT)
	@echo "demo: report in $(DEMO_OUT)/report.html (with the scenario search), figures in $(DEMO_OUT)/figures, closed-loop runs (and frames) in $(DEMO_OUT)/drive"

# Planning, training, closed loop, CRASH and the demo campaign, against BENCH_REF (default: the
# previous commit) checked out in a temporary worktree, in one invocation: experiments/results/bench.md
BENCH_REF ?= HEAD~1
bench: $(STAMP)
	$(BIN)/python experiments/bench_all.py --reference $(BENCH_REF)

# The documentation site (mkdocs.yml, docs/) into site/: --strict turns every broken link, reference
# or docstring warning into an error. The CLI reference is generated from the parsers at build time
# (docs/hooks/cli_reference.py). NO_MKDOCS_2_WARNING silences mkdocs-material's banner about its successor.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

clean:
	rm -rf out site .pytest_cache
