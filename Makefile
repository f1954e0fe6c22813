# The two commands of the README: `make app` and `make test`. Each bootstraps .venv by itself.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
HOST ?= 127.0.0.1
PORT ?= 8080
LINT_PATHS := simcore app tests scripts assets docs/hooks validation setup.py
JS_FILES := $(wildcard app/static/*.js)
# the optional extras of pyproject.toml but those named, comma-separated (deptry takes an extra
# named here as a development one: one imported from the folder it scans is an error)
extras_but = $(shell $(BIN)/python -c 'import sys, tomllib; x = tomllib.load(open("pyproject.toml", "rb"))["project"]["optional-dependencies"]; print(",".join(e for e in x if e not in sys.argv[1:]))' $(1))

.PHONY: app test test-fast bench soak lint docs format chromium clean validate

# The first run creates .venv and installs the project and its dependencies into it (about
# 3 minutes with a fast connection: numpy, scipy, VTK and trame are large); later runs start at once.
$(STAMP): pyproject.toml setup.py
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "lmapd-sim needs Python >= 3.11"'
	@if [ -x $(BIN)/python ]; then \
		echo "make: updating the environment in $(VENV)/ (pyproject.toml or setup.py changed)"; \
	else \
		echo "make: creating the Python environment in $(VENV)/ (first run only)"; \
		$(PYTHON) -m venv $(VENV); \
		echo "make: installing lmapd-sim and its dependencies into $(VENV)/ (first run: about 3 minutes)"; \
	fi
	@$(BIN)/pip install --quiet --upgrade pip 'setuptools>=77'
	$(BIN)/pip install --quiet -e '.[app,test,docs]'
	@touch $(STAMP)
	@echo "make: environment ready"

## make app: serve the app on http://127.0.0.1:8080 with the built-in paper scene
##   make app PORT=8090           another port
##   make app HOST=0.0.0.0        reachable from other machines (a classroom): see the docs
app: $(STAMP)
	@echo "make: starting the app on $(HOST):$(PORT); it prints its address when it is ready (about 3 s). Ctrl+C stops it"
	$(BIN)/lmapd app --host $(HOST) --port $(PORT)

## make test: every test, the browser test in Debian's headless Chromium included, on
## TEST_WORKERS pytest processes (pytest-xdist; each test file on one of them)
##   make test TEST_WORKERS=0     in one process
TEST_WORKERS ?= 2
test: $(STAMP) chromium
	$(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder

## make test-fast: the edit-test loop: every test but the browser tests and those marked slow
## (pytest -m "not browser and not slow"; the markers: pyproject.toml), no Chromium needed.
## `make test` still runs everything; CI runs that
test-fast: $(STAMP)
	$(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder -m "not browser and not slow"

## make bench: the core's stage timings (docs/performance.md)
bench: $(STAMP)
	$(BIN)/lmapd bench

## make soak: 300 rapid slider changes in headless Chromium, then the figures of docs/app.md
soak: $(STAMP) chromium
	$(BIN)/python scripts/soak_app.py

## make validate: the echo stage checked against Mitsuba 3 with mitransient (docs/validation.md):
## installs the validate extra (Mitsuba's LLVM variant needs libLLVM >= 16: Debian's libllvm19,
## installed here when run as root), renders the plates and the MRO, compares them with the
## echo stage and writes docs/data/validation.json (about 5 minutes on two cores). Not part of
## make test.
##   make validate DRJIT_LIBLLVM_PATH=/path/to/libLLVM.so    another LLVM
VALIDATE_STAMP := $(VENV)/.validate-stamp
LIBLLVM := /usr/lib/x86_64-linux-gnu/libLLVM-19.so
DRJIT_LIBLLVM_PATH ?= $(LIBLLVM)
$(VALIDATE_STAMP): $(STAMP)
	$(BIN)/pip install --quiet -e '.[app,test,docs,validate]'
	@touch $(VALIDATE_STAMP)

validate: $(VALIDATE_STAMP)
	@if [ ! -e "$(DRJIT_LIBLLVM_PATH)" ]; then \
		if [ "$(DRJIT_LIBLLVM_PATH)" = "$(LIBLLVM)" ] && [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
			echo "installing Debian's libllvm19 for Mitsuba's LLVM variant"; \
			apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null; \
		else \
			echo "Mitsuba's LLVM variant needs libLLVM 16 or newer, not found at $(DRJIT_LIBLLVM_PATH): sudo apt-get install libllvm19, or make validate DRJIT_LIBLLVM_PATH=/path/to/libLLVM.so"; \
			exit 1; \
		fi; \
	fi
	DRJIT_LIBLLVM_PATH=$(DRJIT_LIBLLVM_PATH) $(BIN)/python -m validation

## make lint: what CI checks before the tests: ruff (lint, unused noqa, format), mypy on simcore/,
## the import layers (import-linter's contracts, [tool.importlinter] in pyproject.toml), the
## dependencies (deptry, [tool.deptry]: every import declared and every dependency used; simcore/
## imports the core only, app/ the core and the app extra, scripts/ and tests/ not the docs') and the page's scripts parsed by Node.js
## (node --check; Debian's nodejs). tests/test_import_layout.py and tests/test_dependencies.py
## run the same two checks in `make test`.
lint: $(STAMP)
	$(BIN)/ruff check $(LINT_PATHS)
	$(BIN)/ruff format --check $(LINT_PATHS)
	$(BIN)/mypy
	$(BIN)/lint-imports --no-cache --no-logo
	$(BIN)/deptry simcore app scripts $(wildcard validation) tests $(filter-out %__pycache__/,$(wildcard tests/*/))
	$(BIN)/deptry simcore --optional-dependencies-dev-groups $(call extras_but)
	$(BIN)/deptry app --optional-dependencies-dev-groups $(call extras_but,app) --ignore DEP002
	$(if $(wildcard validation),$(BIN)/deptry validation --optional-dependencies-dev-groups $(call extras_but,validate) --ignore DEP002)
	@for f in $(JS_FILES); do node --check $$f || exit 1; done; echo "node --check: $(words $(JS_FILES)) scripts parse"

## make docs: the documentation site (docs/, MkDocs Material) built offline into site/; a broken
## link or a generated part that fails stops the build (--strict)
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

format: $(STAMP)
	$(BIN)/ruff format $(LINT_PATHS)

# The browser test needs Chromium from Debian (never `playwright install`): install it if missing.
chromium:
	@if [ -x /usr/bin/chromium ]; then exit 0; fi; \
	if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "installing Debian's chromium for the browser test"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	else \
		echo "The browser test needs Debian's chromium at /usr/bin/chromium: sudo apt-get install chromium"; \
		exit 1; \
	fi

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .mypy_cache .hypothesis *.egg-info site
