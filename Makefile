# Two entry points on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
export MPLBACKEND ?= Agg

.PHONY: demo test test-fast bench lint clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e ".[test,fast]"
	touch $(STAMP)

# Compile the Numba kernels into the package's kernel cache (NUMBA_CACHE_DIR if set, else
# ~/.cache/ntncontact/numba: the package chooses it, for make, the command and pytest alike) on
# two processes (~35-40 s the first time;
# otherwise the first run pays about a minute for them on one core) and write the package's
# bytecode (not written at run time where PYTHONDONTWRITEBYTECODE is set). Done again whenever
# a source file changed: ~2 s when only the edited modules' kernels need compiling again.
SOURCES := $(shell find src -name '*.py')
WARM := $(VENV)/.warm
$(WARM): $(STAMP) $(SOURCES)
	$(BIN)/python -m ntncontact.warmup
	touch $(WARM)

demo: $(WARM)
	$(BIN)/ntncontact run examples/ring_impact.toml --out results/ring_impact --overwrite \
		--gif --times 0.075 0.145 0.285 0.425 0.565 0.805 --compare
	@echo "Ring impact (report 6.4) done. Pictures: results/ring_impact/*.png and animation.gif;"
	@echo "ParaView: open results/ring_impact/fields.pvd; numbers: history.csv, contact.csv, summary.json"

# The suite on one pytest worker per core (pytest-xdist), each test file on one worker, so
# that a file's module fixtures (one simulation shared by its tests) run once: ~1,100 tests
# in 10.1 min on this 2-core machine against 15 min on one worker (session 15). The files are
# handed out in the order tests/conftest.py sets, those with a slow test first, so that the
# longest file starts first and the other worker runs the rest beside it (xdist's default
# order, most tests first, left it for last: session 23, 22.8 min of wall). The ten slowest
# tests are listed at the end. Each worker runs its tests on one thread (OMP_NUM_THREADS=1, as
# Dask's workers do): the workers already fill the cores, and a refined run's assembly (and
# PARDISO) threads on top of them took the suite from 9.3 to 11.3 min (session 30). The tests
# of the threaded paths set their threads themselves.
PYTEST := OMP_NUM_THREADS=1 $(BIN)/python -m pytest -q -n auto --dist loadfile \
	--no-loadscope-reorder --durations=10

test: $(WARM)
	$(PYTEST)

test-fast: $(WARM)
	$(PYTEST) -m "not slow"

bench: $(WARM)
	$(BIN)/python -m pip install --quiet -e ".[bench,fast]"
	$(BIN)/python benchmarks/run.py
	$(BIN)/python benchmarks/scaling.py --k 1 2 4 8
	$(BIN)/python benchmarks/calculix.py  # CalculiX comparison; one line and skipped without ccx

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks

clean:
	rm -rf $(VENV) results
