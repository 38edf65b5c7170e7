# The two commands a new user runs (README): `make demo` and `make test`. Without make (Windows,
# PowerShell): `uv run lab demo` and `uv run pytest -n auto --durations=15`, the same commands.
# uv makes .venv from uv.lock, the versions CI tested, with a Python 3.11-3.13 (it installs one when
# none is there); nothing is compiled (pyproject.toml: [tool.uv] no-build).
# uv: the one on PATH, else the project's own copy in .tools/bin (make setup gets it there: no root).
TOOLS   := $(CURDIR)/.tools
UV      ?= $(shell command -v uv 2>/dev/null || echo $(TOOLS)/bin/uv)
RUN     := $(UV) run --locked
# pytest-xdist on the machine's cores (make test JOBS=0: one process); --durations: the slowest tests.
# Measured on a fresh clone, 2 shared cores: 604 tests in 1046 s with one process, 623 s with -n auto.
# Workers share the test cache (.lab-cache-test): a database, table or landmark database is built under
# a lock file beside it and written through a temporary file (lab/training/cache.py), so two workers on a
# cold cache build each once (the second waits and reads it; a list of them they split), never half a file.
JOBS    ?= auto
PYTEST  := $(RUN) pytest -q -n $(JOBS) --durations=15

.PHONY: demo test test-fast notebooks bench lint lock check-wheels clean setup

# Before uv: uv itself (when it is not installed: into .tools/, a folder of this project, from PyPI
# through a venv of python3, else pip --target, else uv's installer; no root), and a Python in the
# supported range (else one line saying what to install).
setup:
	@command -v "$(UV)" >/dev/null 2>&1 || { \
	  echo "make: uv is not installed; getting it into $(TOOLS) (a folder of this project; no root needed)"; \
	  mkdir -p "$(TOOLS)/bin"; \
	  { python3 -m venv "$(TOOLS)/venv" && "$(TOOLS)/venv/bin/python" -m pip install --quiet --disable-pip-version-check uv \
	    && ln -sf ../venv/bin/uv "$(TOOLS)/bin/uv"; } \
	  || { python3 -m pip install --quiet --disable-pip-version-check --target "$(TOOLS)/pip" uv \
	    && ln -sf ../pip/bin/uv "$(TOOLS)/bin/uv"; } \
	  || { command -v curl >/dev/null 2>&1 && curl -LsSf https://astral.sh/uv/install.sh \
	    | env UV_INSTALL_DIR="$(TOOLS)/bin" UV_NO_MODIFY_PATH=1 sh; } \
	  || { echo "make: could not get uv (no python3 venv or pip, no download); install it: python3 -m pip install uv (or see https://docs.astral.sh/uv/getting-started/installation/)" >&2; exit 1; }; \
	  "$(UV)" --version; }
	@$(UV) python find >/dev/null 2>&1 || $(UV) python install --quiet 2>/dev/null || { echo "make: lab needs Python 3.11-3.13 and found $$(python3 --version 2>/dev/null || echo no python3), and uv could not download one; install Python 3.12 (python.org, your package manager, or uv python install 3.12 where downloads work)" >&2; exit 1; }

demo: setup
	$(RUN) lab demo --out out/demo
	@echo "make demo: to see the run in 3D (one HTML page, offline): $(UV) run --extra view3d lab demo --out out/demo --view3d out/demo/view3d.html"

test: setup
	$(PYTEST)

test-fast: setup
	$(PYTEST) -m "not slow"

notebooks: setup
	$(RUN) --extra notebooks lab notebooks

bench: setup
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(RUN) python $$b || exit 1; done

lint: setup
	$(RUN) ruff check lab tests benchmarks

# Refresh the pins (then `make check-wheels`, run the tests, commit uv.lock).
lock:
	$(UV) lock --upgrade

# What CI checks: every supported platform and Python resolves to wheels (needs https://pypi.org).
check-wheels:
	python3 .ci/check_wheels.py

clean:
	rm -rf .venv out .pytest_cache .tools
