# Two-command set-up: `make demo` and `make test` each build .venv from nothing when needed.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.fbia-installed
TYPECHECK := build/typecheck

.PHONY: demo test test-slow lint typecheck pytest bench clean reproduce docs package-tree

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[all,test,docs]'
	@touch $(STAMP)

# The flow-cell example: Levenberg-Marquardt with the finite-element FSI model (seconds with
# warm starts), LM with the closed-form stand-in from all eleven Table 1 starts (seconds), and
# the Bayesian GP + SMC calibration of Paper B with ale_fsi on an adaptive design (about a minute).
demo: $(STAMP)
	$(BIN)/fbia run examples/flow_cell/study_fsi.toml
	$(BIN)/fbia run examples/flow_cell/study.toml
	$(BIN)/fbia run examples/flow_cell/study_bayes.toml

test: lint typecheck pytest

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# The package as it is installed, as a tree of symlinks (the repository root is the package):
# what mypy and the API reference read.
package-tree:
	@rm -rf $(TYPECHECK) && mkdir -p $(TYPECHECK)/fbia
	@for d in core execution storage figures imaging studies plugins measures iterators testing; do ln -s ../../../$$d $(TYPECHECK)/fbia/$$d; done
	@ln -s ../../../__init__.py $(TYPECHECK)/fbia/__init__.py
	@for f in pytest_plugin.py; do ln -s ../../../$$f $(TYPECHECK)/fbia/$$f; done

# mypy checks every package of fbia (core, plugins, measures, iterators, testing).
typecheck: $(STAMP) package-tree
	MYPYPATH=$(TYPECHECK) $(BIN)/mypy -p fbia

# The guides of docs/ and the API reference from the docstrings (mkdocs.yml), into build/site;
# a warning (a broken docstring, a reference that resolves to nothing) fails the build.
docs: $(STAMP) package-tree
	$(BIN)/mkdocs build --strict

# The suite in TEST_WORKERS processes (pytest-xdist): 2 for the 2-core machine of the goal
# (measured at stop 38: 386 s against 575 s in one process, all 1354 tests passing).
TEST_WORKERS ?= 2
pytest: $(STAMP)
	$(BIN)/pytest -n $(TEST_WORKERS)

# Long verification runs (finer meshes, full studies): not part of `make test`.
# The slow tests, and report.html in a real browser: Debian's chromium (installed here when
# missing; needs root or sudo) driven by Playwright's driver (the `browser` extra).
CHROMIUM ?= /usr/bin/chromium
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
test-slow: $(STAMP)
	@test -x $(CHROMIUM) || $(SUDO) apt-get install -y -q chromium || \
	  (echo "test-slow: $(CHROMIUM) missing and could not be installed (Debian: apt-get install chromium)" >&2; exit 2)
	$(BIN)/python -m pip install --quiet -e '.[browser]'
	$(BIN)/pytest -m slow

# The papers' examples (examples/paper_*/<example>/study*.toml and Paper A's growth example
# examples/growth/study*.toml): long (see each example's README for its measured time);
# every study runs on its own [executor], so `kind = "dask"` spreads it over a cluster. Then
# docs/reproductions.md.
REPRODUCE ?= $(sort $(wildcard examples/paper_*/*/study*.toml examples/growth/study*.toml))
# REPRODUCE_FLAGS: options of each fbia run, e.g. --fresh after the model's code changed (a
# store of runs made by other code is refused, exit status 2)
REPRODUCE_FLAGS ?=
reproduce: $(STAMP)
	@# exit status 3 (not trustworthy) and 4 (no result) are findings the summary reports;
	@# anything else (an error, bad input, an interruption) stops the loop
	@for f in $(REPRODUCE); do echo "== $$f"; $(BIN)/fbia run $(REPRODUCE_FLAGS) $$f; s=$$?; \
	  if [ $$s -ne 0 ] && [ $$s -ne 3 ] && [ $$s -ne 4 ]; then exit $$s; fi; done
	$(BIN)/fbia reproductions docs/reproductions.md $(sort $(wildcard examples/paper_*)) examples/growth

bench: $(STAMP)
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

clean:
	rm -rf $(VENV) build *.egg-info output
