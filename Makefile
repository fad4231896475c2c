# physpose: `make demo` (install + run on the built-in clip), `make test` (install + tests).
SHELL := /bin/bash
UV := $(shell command -v uv 2>/dev/null || echo $(HOME)/.local/bin/uv)
RUN := $(UV) run --frozen

.PHONY: setup web data demo test test-fast bench clean

$(UV):
	python3 -m pip install --user --quiet "uv>=0.5" || python3 -m pip install --quiet "uv>=0.5"

setup: $(UV) web
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
