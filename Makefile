# physpose: `make demo` (install + run on the built-in clip), `make test` (install + tests).
SHELL := /bin/bash
# uv from PATH, else the copy `pip install uv` puts beside python3 (run as `python3 -m uv`).
UV := $(or $(shell command -v uv 2>/dev/null),python3 -m uv)
RUN := $(UV) run --frozen

.PHONY: setup uv web data demo test test-fast bench clean

uv:
	@$(UV) --version >/dev/null 2>&1 || python3 -m pip install --quiet "uv>=0.5"

setup: uv web
	$(UV) sync --frozen
	$(RUN) python -m physpose.demo_data

# The report's viewer: three.js + web/src bundled by esbuild into one file (git-ignored).
VIEWER := src/physpose/report/assets/viewer.js
web: $(VIEWER)

$(VIEWER): web/package.json web/package-lock.json $(wildcard web/src/*.js)
	cd web && npm ci --no-audit --no-fund && npm run build

data: setup

demo: setup
	$(RUN) physpose demo --out out/demo

test: setup
	$(RUN) pytest -q

test-fast: setup
	$(RUN) pytest -q -m "not slow"

bench: setup
	$(RUN) physpose benchmark --out out/benchmark

clean:
	rm -rf out .cache
