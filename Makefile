# prioik: `make test` and `make demo` build .venv from pyproject.toml themselves
# (re-installing only when pyproject.toml changed) and then run.
# .venv holds every extra (`pip install -e ".[all,test]"`); `make test` also builds
# .venv-core, the core alone (`pip install -e .` and pytest), and runs tests/core there,
# beside the full suite.
# The compiled core (core/, prioik._core) is built by pip through scikit-build-core and
# CMake: .venv holds the build requirements and builds without isolation into build/, so
# that an edit to core/ rebuilds only what changed (`make venv` after the edit does it).

PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
CORE_VENV  := .venv-core
CORE_PY    := $(CORE_VENV)/bin/python
CORE_STAMP := $(CORE_VENV)/.installed
CORE_VENV_BUILT := $(CORE_VENV)/.core-built
OUT    ?= results

CORE_STAMP_BUILT := $(VENV)/.core-built
CORE_SOURCES := $(shell find core -type f -not -name '*~' 2>/dev/null)
# pyproject.toml's [build-system] requires, and CMake and Ninja (kept in the venv: their
# paths stay the same from one build to the next)
BUILD_REQUIRES = $$($(PY) -c "import tomllib; print(*tomllib.load(open('pyproject.toml', 'rb'))['build-system']['requires'])") "cmake>=3.18" "ninja>=1.10"

# scikit-build-core's editable install also writes the package sources' parent
# directories into its .pth (for Cython's cimports), which would expose hierarchy/,
# formulations/, ... (and the repository's parent) as top-level modules; its import
# finder alone serves `prioik`, so only the .pth's `import` line is kept
# (tests/test_namespace.py: no top-level packages)
EDITABLE_PATHS_OFF = -c "import pathlib, sysconfig; p = pathlib.Path(sysconfig.get_paths()['purelib'], '_editable_skbc_prioik.pth'); p.write_text(''.join(l for l in p.read_text().splitlines(True) if l.startswith('import ')))"

.PHONY: test test-core test-forced-cpu demo docs venv venv-core tsid clean asan asan-bindings \
	replay-screenshot lint docs-commands

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet $(BUILD_REQUIRES)
	$(PY) -m pip install --quiet --no-build-isolation -e ".[all,test]"
	$(PY) $(EDITABLE_PATHS_OFF)
	touch $(STAMP) $(CORE_STAMP_BUILT)

# an edit to core/: the extension rebuilt (only what changed) and re-installed
$(CORE_STAMP_BUILT): $(STAMP) $(CORE_SOURCES)
	@start=$$(date +%s); \
	$(PY) -m pip install --quiet --no-build-isolation --no-deps -e . && \
	$(PY) $(EDITABLE_PATHS_OFF) && \
	echo "prioik._core rebuilt in $$(( $$(date +%s) - start )) s"
	touch $(CORE_STAMP_BUILT)

# Built anew whenever pyproject.toml changes, so that nothing an older core pulled in
# stays behind; prints its build time and size.
$(CORE_STAMP): pyproject.toml
	@start=$$(date +%s); \
	rm -rf $(CORE_VENV) && $(PYTHON) -m venv $(CORE_VENV) && \
	$(CORE_PY) -m pip install --quiet -C build-dir=build/venv-core-{wheel_tag} -e . "pytest>=7" && \
	$(CORE_PY) $(EDITABLE_PATHS_OFF) && \
	echo "$(CORE_VENV) (core + pytest) built in $$(( $$(date +%s) - start )) s; $$(du -sh $(CORE_VENV) | cut -f1)"
	touch $(CORE_STAMP) $(CORE_VENV_BUILT)

venv: $(STAMP) $(CORE_STAMP_BUILT)

# The TSID baseline's own environment (benchmarks/tsid_baseline.py): tsid 1.7.1 binds
# pin 3.4.0, which cannot share .venv's pin 3.8.0. Its python runs
# benchmarks/tsid_runner.py in a subprocess; without it the TSID rows say "not
# installed". The packages are tsid_baseline.REQUIREMENTS (tests/test_tsid_baseline.py
# checks that the two lists agree); prints its build time and size.
TSID_VENV     := .venv-tsid
TSID_STAMP    := $(TSID_VENV)/.installed
TSID_REQUIRES := "tsid==1.7.1" "pin==3.4.0" "cmeel-urdfdom>=4,<5" "cmeel-tinyxml2>=10,<11"

# built when missing or when TSID_REQUIRES changed (the stamp holds the list)
tsid:
	@if [ "$$(cat $(TSID_STAMP) 2>/dev/null)" != '$(TSID_REQUIRES)' ]; then \
	start=$$(date +%s); \
	rm -rf $(TSID_VENV) && $(PYTHON) -m venv $(TSID_VENV) && \
	$(TSID_VENV)/bin/python -m pip install --quiet $(TSID_REQUIRES) && \
	$(TSID_VENV)/bin/python -c "from tsid import tsid_pywrap" && \
	echo '$(TSID_REQUIRES)' > $(TSID_STAMP) && \
	echo "$(TSID_VENV) (tsid, pin) built in $$(( $$(date +%s) - start )) s; $$(du -sh $(TSID_VENV) | cut -f1)"; \
	fi

# an edit to core/: the core environment's extension rebuilt in its build directory
# (only what changed), so that tests/core never runs a stale core
$(CORE_VENV_BUILT): $(CORE_STAMP) $(CORE_SOURCES)
	@start=$$(date +%s); \
	$(CORE_PY) -m pip install --quiet --no-deps -C build-dir=build/venv-core-{wheel_tag} -e . && \
	$(CORE_PY) $(EDITABLE_PATHS_OFF) && \
	echo "$(CORE_VENV)'s prioik._core rebuilt in $$(( $$(date +%s) - start )) s"
	touch $(CORE_VENV_BUILT)

venv-core: $(CORE_STAMP) $(CORE_VENV_BUILT)

CORE_TEST := $(CORE_PY) -m pytest -q -p no:cacheprovider tests/core

test-core: $(CORE_STAMP) $(CORE_VENV_BUILT)
	$(CORE_TEST)

# The core's tests run beside the full suite (side by side on two cores the wall time is
# the full suite's); the core's output follows the suite's.
test: $(STAMP) $(CORE_STAMP_BUILT) $(CORE_STAMP) $(CORE_VENV_BUILT) lint
	@$(CORE_TEST) > $(CORE_VENV)/test-core.log 2>&1 & core=$$!; \
	$(PY) -m pytest -q -p no:cacheprovider; full=$$?; \
	wait $$core; status=$$?; \
	echo "--- tests/core in $(CORE_VENV) (the core alone):"; cat $(CORE_VENV)/test-core.log; \
	test $$full -eq 0 && test $$status -eq 0

# The C++ core alone (core/, no Python), built with -fsanitize=address,undefined, and its
# tests run under the sanitizers (ctest: the core's tests and the example program)
ASAN_DIR := build/asan
asan: $(STAMP)
	$(VENV)/bin/cmake -S core -B $(ASAN_DIR) -G Ninja -DCMAKE_MAKE_PROGRAM=$(abspath $(VENV)/bin/ninja) \
		-DCMAKE_BUILD_TYPE=RelWithDebInfo -DPRIOIK_SANITIZE=ON -DPRIOIK_BUILD_TESTS=ON \
		-DPython_EXECUTABLE=$(abspath $(PY))
	$(VENV)/bin/cmake --build $(ASAN_DIR)
	ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
		$(VENV)/bin/ctest --test-dir $(ASAN_DIR) --output-on-failure

# The modules marked `rounding_edge` again, on another machine's arithmetic: OpenBLAS on
# its Sandybridge kernels (AVX, no FMA). The C++ core has one rounding rule (IEEE, no
# contraction, a portable build): nothing of it to force. A test there asserts what holds
# whichever way a rounding edge goes. CI runs it after `make test`.
FORCED_CPU := OPENBLAS_CORETYPE=Sandybridge

test-forced-cpu: $(STAMP) $(CORE_STAMP_BUILT)
	$(FORCED_CPU) $(PY) -m pytest -p no:cacheprovider -m "rounding_edge and not slow"

# ruff (E, F, I, B, UP) over the whole tree, and mypy over the public API
# (prioik.__all__ comes from prioik, prioik.hierarchy and prioik.formulations), read
# through build/typecheck: symlinks laid out as the installed package, whose top-level
# source folders are sub-packages of prioik
TYPECHECK := build/typecheck
lint: $(STAMP)
	$(VENV)/bin/ruff check --quiet .
	rm -rf $(TYPECHECK) && mkdir -p $(TYPECHECK)/prioik
	for f in prioik/*.py; do ln -s $(abspath .)/$$f $(TYPECHECK)/prioik/; done
	for d in hierarchy formulations robots benchmarks; do ln -s $(abspath .)/$$d $(TYPECHECK)/prioik/$$d; done
	cd $(TYPECHECK) && $(abspath $(VENV))/bin/mypy --config-file $(abspath pyproject.toml) \
		-m prioik -m prioik.extras -p prioik.hierarchy -p prioik.formulations

demo: $(STAMP) $(CORE_STAMP_BUILT)
	$(VENV)/bin/prioik fencing --variant both --out $(OUT)

# The documentation site (mkdocs.yml, the `docs` extra) built into site/: open
# site/index.html. `make test` builds it too, with warnings as errors (tests/test_docs.py).
# NO_MKDOCS_2_WARNING: Material for MkDocs' banner about MkDocs 2.0, not about this site
docs: $(STAMP) $(CORE_STAMP_BUILT)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --site-dir site

# Every command README.md and the site's user pages show, run as written at full size
# (tests/test_doc_commands.py with PRIOIK_SMOKE=0; `make test` runs them shrunk to a few
# steps), each page's commands in a folder of DOC_COMMANDS_DIR with what each printed
# (command-N.log: the figures) beside the pages and plots it wrote, to set beside docs/;
# -s prints each command's time. Over an hour on 2 cores: the shipped sweep alone ~40 min,
# prioik bench and prioik fencing several minutes each, `pip wheel .` ~2 min. A part:
# DOC_COMMANDS_SELECT="-k 'README or scenarios'".
DOC_COMMANDS_DIR ?= build/docs-commands
DOC_COMMANDS_SELECT ?=
docs-commands: $(STAMP) $(CORE_STAMP_BUILT)
	PRIOIK_SMOKE=0 $(PY) -m pytest -p no:cacheprovider -s -v tests/test_doc_commands.py \
		--basetemp=$(DOC_COMMANDS_DIR) $(DOC_COMMANDS_SELECT)

# README's screenshot of the meshed replay: the G1 fencing run (extended_jacobian,
# compatible) in headless chromium, paused 2.6 s into the run
SHOT_DIR := build/replay-screenshot
replay-screenshot: $(STAMP) $(CORE_STAMP_BUILT)
	$(VENV)/bin/prioik fencing --variant compatible --formulations extended_jacobian \
		--out $(SHOT_DIR) --quiet
	chromium --headless --no-sandbox --disable-gpu --hide-scrollbars --window-size=900,560 \
		--virtual-time-budget=1500 --screenshot=docs/img/replay-g1.png \
		"file://$(abspath $(SHOT_DIR))/compatible_replay_meshes.html#run=extended_jacobian&t=2.6"

clean:
	rm -rf $(VENV) $(CORE_VENV) $(TSID_VENV) $(OUT) *.egg-info build site

# The Python extension built with -fsanitize=address,undefined and the row writers'
# Python tests (the plain-Python reference, the bad inputs, a short boundary fuzz) run on it,
# the sanitizer runtimes preloaded (core/tests/sanitized_rows.py)
ASAN_PY_DIR := build/asan-bindings
asan-bindings: $(STAMP)
	$(VENV)/bin/cmake -S core -B $(ASAN_PY_DIR) -G Ninja -DCMAKE_MAKE_PROGRAM=$(abspath $(VENV)/bin/ninja) \
		-DCMAKE_BUILD_TYPE=RelWithDebInfo -DPRIOIK_SANITIZE=ON -DPRIOIK_PYTHON=ON \
		-DPython_EXECUTABLE=$(abspath $(PY)) -Dnanobind_DIR=$$($(PY) -m nanobind --cmake_dir)
	$(VENV)/bin/cmake --build $(ASAN_PY_DIR) --target _core
	LD_PRELOAD=$$($(CXX) -print-file-name=libasan.so):$$($(CXX) -print-file-name=libubsan.so) \
		ASAN_OPTIONS=detect_leaks=0:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
		$(PY) core/tests/sanitized_rows.py $$(ls $(ASAN_PY_DIR)/_core*.so)
