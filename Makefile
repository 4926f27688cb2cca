# Two entry points on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# Python keeps the bytecode of what it imports even where the environment says not to (PYTHONDONTWRITEBYTECODE):
# the suite's workers and the processes they start then read torch's and Drake's modules compiled once, instead of
# compiling them each time (about 8 s of CPU per process on the 2-core machine).
unexport PYTHONDONTWRITEBYTECODE

.PHONY: demo test lint install clean

$(STAMP): pyproject.toml
	# A venv without the bundled pip: the interpreter's own pip puts the current one in, which installs faster.
	test -x $(BIN)/python || $(PYTHON) -m venv --without-pip $(VENV) || python3 -m venv --without-pip $(VENV)
	test -x $(BIN)/pip || $(PYTHON) -m pip --python $(BIN)/python install --quiet --no-compile --upgrade pip \
		|| $(BIN)/python -m ensurepip --upgrade
	# One resolve: torch pinned to the CPU build that lies on this disk (an unpinned torch pulls CUDA); dev (pytest,
	# ruff, mypy) and ray (the suite checks that Ray and the local process pool collect alike). No bytecode
	# compiled now: Python compiles what it imports.
	$(BIN)/pip install --quiet --no-compile torch==2.13.0 -e '.[dev,ray]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/tamp demo

# The checkers first (their paths and rules are in pyproject.toml); a lint error stops before the tests.
lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

# Everything: ruff (a finding stops here), then mypy beside the whole suite (the simulator and slow tests
# included; see BUILD_NOTES.md for `-m "not sim"` and `-m "not slow"`) on two pytest-xdist workers: the tests
# of a file that share a module-scoped fixture stay on one worker (tests/conftest.py). mypy is one process and
# the suite's workers leave a core idle while they start and end, so beside it mypy costs little time; its
# findings are printed after the suite, and either failing fails `make test`.
test: $(STAMP)
	$(BIN)/ruff check .
	@$(BIN)/mypy > $(VENV)/mypy.log 2>&1 & types=$$!; trap 'kill $$types 2>/dev/null; exit 130' INT TERM; \
	$(BIN)/python -m pytest -q -n 2; tests=$$?; \
	wait $$types; typed=$$?; echo "mypy:"; cat $(VENV)/mypy.log; \
	test $$tests -eq 0 && test $$typed -eq 0

clean:
	rm -rf $(VENV) *.egg-info
