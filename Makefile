# physpose: `make demo` (install + run on the built-in clip), `make test` (install + tests).
SHELL := /bin/bash
# uv from PATH, else a private copy in .tools/ (where an "externally managed" system Python,
# as Debian's, refuses `pip install`), else the one `pip install uv` put beside python3.
# Expanded at each use (=, not :=), so the recipes after `uv` see what it installed.
UV = $(shell command -v uv 2>/dev/null || { [ -x .tools/bin/uv ] && echo .tools/bin/uv; } \
       || echo python3 -m uv)
RUN = $(UV) run --frozen

.PHONY: setup uv web data demo test test-fast bench clean

uv:
	@$(UV) --version >/dev/null 2>&1 || python3 -m pip install --quiet "uv>=0.5" 2>/dev/null \
	  || { python3 -m venv .tools && .tools/bin/pip install --quiet "uv>=0.5"; } \
	  || { echo "cannot install uv: install it (https://docs.astral.sh/uv/) or Python's venv" \
	            "module (Debian: apt install python3-venv), then run make again" >&2; exit 1; }

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
	rm -rf out .cache .tools
