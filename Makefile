# Two entry points (see README "Quick start"): `make demo` and `make test`; `make docs` builds the site.
# Each creates .venv on first use with the project and its dev extras.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.frbjax-installed

.PHONY: demo test docs bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/frbjax demo

# pytest exits 5 when it collects no test; that is reported, not hidden.  OpenBLAS (scipy's, which
# jaxlib's LAPACK calls use) gets one thread: its threads gain nothing in these tests and, spinning
# beside the other worker, made two light-curve inversions take over 300 s each instead of 136 s.
# Each test file runs on one worker (--dist loadfile), so that a module's fixtures (the tensor
# derivatives' diffrax stencil: 4 minutes) are computed once.  (pytest-xdist 3.8's loadgroup does
# not group under pytest 9: it renames items through an attribute pytest 9 no longer reads.)
# A test that runs past 20 minutes (the longest, with its fixture, takes about 5) fails with every
# thread's stack printed, instead of holding the run until CI's limit.
test: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -n 2 --dist loadfile -q --durations=15 \
		--timeout 1200 --timeout-method thread tests; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "pytest collected no tests"; fi; exit $$rc

# The documentation site into site/, with every warning an error (mkdocs.yml sets strict too).
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict --site-dir site

bench: $(STAMP)
	$(BIN)/python benchmarks/special.py

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis site
