# Two entry points (see README "Quick start"): `make demo` and `make test`; `make docs` builds the site.
# Each creates .venv on first use with the project and its dev extras.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.frbjax-installed

.PHONY: demo lint typecheck test test-slow test-all test-floor docs bench clean

# The compiled kernels (csrc/, CMakeLists.txt) are built by the install: a change to them reinstalls.
$(STAMP): pyproject.toml CMakeLists.txt $(wildcard csrc/*)
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/frbjax demo

# pytest exits 5 when it collects no test; that is reported, not hidden.  OpenBLAS (scipy's, which
# jaxlib's LAPACK calls use) gets one thread: its threads gain nothing in these tests and, spinning
# beside the other worker, made two light-curve inversions take over 300 s each instead of 136 s.
# Each test file runs on one worker (--dist loadfile), so that a module's fixtures are computed once;
# the files go out longest first (tests/_schedule.py; --no-loadscope-reorder keeps that order).
# (pytest-xdist 3.8's loadgroup does not group under pytest 9: it renames items through an attribute
# pytest 9 no longer reads.)
# `make lint` (seconds; `make test` runs it first): ruff's rules and format, as pyproject.toml sets
# them.  `ruff format .` and `ruff check --fix .` repair most of what it reports.
lint: $(STAMP)
	$(BIN)/ruff check . && $(BIN)/ruff format --check .

# `make typecheck`: pyright (basic) over a user's calls of the public API (tests/typing/), which checks
# the package's annotations as a type checker sees them (about 10 s; pyright fetches its Node package
# on first use).
typecheck: $(STAMP)
	$(BIN)/pyright -p tests/typing

# Two tiers, as scipy's `-m full` and diffrax's slow tests: `make test` (what CI runs) leaves out the
# tests marked slow, the ones that compile a whole light-curve inversion, the tensor derivatives'
# programs, a notebook or a benchmark end to end (each over a minute); `make test-slow` runs those,
# and `make test-all` both.  The time budget (tests/_time_budget.py, the lesser of CPU and wall
# seconds): a test whose setup and call take over 60 s fails unless marked slow, and the slow tests
# must stay under SLOW_TOTAL together (the run prints their total).  A test that runs past 10 minutes,
# hung, fails with every thread's stack printed, instead of holding the run until CI's limit; a worker
# that crashes ends the run (--max-worker-restart 0) with its report, where replacing it could leave
# the run waiting until CI's limit (seen with pytest-xdist 3.8 and --dist loadfile).
PYTEST := OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -n 2 --dist loadfile --no-loadscope-reorder --max-worker-restart 0 -q \
	--durations=15 --timeout 600 --timeout-method thread
# 240 s since 2026-12-05: the SAM light-curve inversion also solves its winner on the finer shape (the
# shape's resolution error, one Levenberg-Marquardt solve with 1288 parameters: 77 s against about
# 25 s); the tier measured 226 s then (150 s before).
SLOW_TOTAL ?= 240
test: $(STAMP) lint
	$(PYTEST) -m "not slow" tests; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "pytest collected no tests"; fi; exit $$rc

test-slow: $(STAMP)
	FRBJAX_SLOW_TOTAL_LIMIT=$(SLOW_TOTAL) $(PYTEST) -m slow tests; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "pytest collected no tests"; fi; exit $$rc

test-all: $(STAMP)
	FRBJAX_SLOW_TOTAL_LIMIT=$(SLOW_TOTAL) $(PYTEST) tests; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "pytest collected no tests"; fi; exit $$rc

# The oldest versions the project declares (pyproject.toml's floors, each `name>=version` pinned to
# `name==version`) in a venv of their own, and a smoke set of the suite against them: the motion and
# its validation, the Jacobi functions, a fit (optimistix), a torque (diffrax), a light curve, a
# posterior (numpyro).  It checks that they work, not how fast: older JAX compiles the suite's
# programs several times slower, so one test may take up to 10 minutes (FRBJAX_TEST_TIME_LIMIT; 60 s
# in `make test`).  The compiled kernels are built again without build isolation, with the floor's
# jaxlib: pip's isolated build takes the newest jaxlib, whose FFI headers jaxlib 0.7.2 refuses
# (frbjax then warns and runs the JAX path).
FLOOR_VENV := .venv-floor
FLOOR_TESTS := tests/test_validation.py tests/special/test_jacobi.py tests/test_fit.py::test_gyro_data \
	tests/test_torques.py::test_damped_sphere_exact_damping_kick tests/test_lightcurve.py::test_periods_against_the_motion \
	tests/test_posterior.py::test_recovery_of_a_triaxial_body
test-floor:
	rm -rf $(FLOOR_VENV)
	$(PYTHON) -m venv $(FLOOR_VENV)
	$(FLOOR_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(FLOOR_VENV)/bin/python -c 'import re, tomllib; \
		floors = [re.fullmatch(r"([A-Za-z0-9_.-]+)>=([^,;]+)", d).groups() for d in tomllib.load(open("pyproject.toml", "rb"))["project"]["dependencies"]]; \
		print("\n".join(f"{name}=={version}" for name, version in floors))' > $(FLOOR_VENV)/constraints.txt
	$(FLOOR_VENV)/bin/python -m pip install --quiet -c $(FLOOR_VENV)/constraints.txt -e . pytest mpmath scikit-build-core
	$(FLOOR_VENV)/bin/python -m pip install --quiet --no-build-isolation --no-deps -e .
	$(FLOOR_VENV)/bin/python -m pip list | grep -E '^(jax|jaxlib|numpy|equinox|jaxtyping|optimistix|diffrax|lineax) '
	OPENBLAS_NUM_THREADS=1 FRBJAX_TEST_TIME_LIMIT=600 $(FLOOR_VENV)/bin/python -m pytest -q -p no:cacheprovider $(FLOOR_TESTS)

# The documentation site into site/, with every warning an error (mkdocs.yml sets strict too).
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict --site-dir site

bench: $(STAMP)
	$(BIN)/python benchmarks/special.py

clean:
	rm -rf $(VENV) $(FLOOR_VENV) .pytest_cache .hypothesis site
