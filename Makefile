# prioik: `make test` and `make demo` build .venv from pyproject.toml themselves
# (re-installing only when pyproject.toml changed) and then run.
# .venv holds every extra (`pip install -e ".[all,test]"`); `make test` also builds
# .venv-core, the core alone (`pip install -e .` and pytest), and runs tests/core there,
# beside the full suite.

PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
CORE_VENV  := .venv-core
CORE_PY    := $(CORE_VENV)/bin/python
CORE_STAMP := $(CORE_VENV)/.installed
OUT    ?= results

.PHONY: test test-core test-forced-cpu demo venv venv-core clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[all,test]"
	touch $(STAMP)

# Built anew whenever pyproject.toml changes, so that nothing an older core pulled in
# stays behind; prints its build time and size.
$(CORE_STAMP): pyproject.toml
	@start=$$(date +%s); \
	rm -rf $(CORE_VENV) && $(PYTHON) -m venv $(CORE_VENV) && \
	$(CORE_PY) -m pip install --quiet -e . "pytest>=7" && \
	echo "$(CORE_VENV) (core + pytest) built in $$(( $$(date +%s) - start )) s; $$(du -sh $(CORE_VENV) | cut -f1)"
	touch $(CORE_STAMP)

venv: $(STAMP)

venv-core: $(CORE_STAMP)

# Its own numba cache: the two environments resolve different numpy versions, and with
# one shared cache (formulations/__pycache__) BufferSolver and solve differed in the last
# bits in .venv on a fresh clone (test_buffer_solver_equals_solve_bit_for_bit).
CORE_TEST := NUMBA_CACHE_DIR=$(CORE_VENV)/numba-cache $(CORE_PY) -m pytest -q -p no:cacheprovider tests/core

test-core: $(CORE_STAMP)
	$(CORE_TEST)

# The core's tests run beside the full suite (each compiles its numba kernels on a fresh
# clone, single-threaded, into its own cache: side by side on two cores the wall time is
# the full suite's); the core's output follows the suite's.
test: $(STAMP) $(CORE_STAMP)
	@$(CORE_TEST) > $(CORE_VENV)/test-core.log 2>&1 & core=$$!; \
	$(PY) -m pytest -q -p no:cacheprovider; full=$$?; \
	wait $$core; status=$$?; \
	echo "--- tests/core in $(CORE_VENV) (the core alone):"; cat $(CORE_VENV)/test-core.log; \
	test $$full -eq 0 && test $$status -eq 0

# The modules marked `rounding_edge` again, on another machine's arithmetic: numba's
# kernels compiled for a generic x86-64 CPU (SSE2, no FMA, no AVX; the host's own
# target is the default) into a cache of their own, and OpenBLAS on its Sandybridge
# kernels (AVX, no FMA). A test there asserts what holds whichever way a rounding edge
# goes. CI runs it after `make test`.
FORCED_CPU := NUMBA_CPU_NAME=generic NUMBA_CACHE_DIR=$(VENV)/numba-cache-generic \
              OPENBLAS_CORETYPE=Sandybridge

test-forced-cpu: $(STAMP)
	$(FORCED_CPU) $(PY) -m pytest -p no:cacheprovider -m "rounding_edge and not slow"

demo: $(STAMP)
	$(VENV)/bin/prioik fencing --variant both --out $(OUT)

clean:
	rm -rf $(VENV) $(CORE_VENV) $(OUT) *.egg-info
