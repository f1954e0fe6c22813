# The two commands of the README: `make app` and `make test`. Each bootstraps .venv by itself.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
HOST ?= 127.0.0.1
PORT ?= 8080

.PHONY: app test bench soak lint format chromium clean

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 11), "lmapd-sim needs Python >= 3.11"'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e '.[app,test]'
	@touch $(STAMP)

## make app: serve the app on http://127.0.0.1:8080 with the built-in paper scene
app: $(STAMP)
	$(BIN)/lmapd app --host $(HOST) --port $(PORT)

## make test: every test, the browser test in Debian's headless Chromium included
test: $(STAMP) chromium
	$(BIN)/python -m pytest

## make bench: the core's stage timings (README table)
bench: $(STAMP)
	$(BIN)/lmapd bench

## make soak: 300 rapid slider changes in headless Chromium, then the figures of the README
soak: $(STAMP) chromium
	$(BIN)/python scripts/soak_app.py

lint: $(STAMP)
	$(BIN)/ruff check simcore app tests
	$(BIN)/ruff format --check simcore app tests

format: $(STAMP)
	$(BIN)/ruff format simcore app tests

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
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis *.egg-info
