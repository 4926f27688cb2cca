# Two entry points on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint install clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	# torch first, pinned: the CPU build that lies on this disk (an unpinned torch pulls CUDA).
	$(BIN)/pip install --quiet torch==2.13.0
	# dev (pytest, ruff, mypy) and ray: the suite checks that Ray and the local process pool collect alike.
	$(BIN)/pip install --quiet -e '.[dev,ray]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/tamp demo

# The checkers first (their paths and rules are in pyproject.toml); a lint error stops before the tests.
lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

# Everything: lint, then the whole suite (the simulator and slow tests included; see BUILD_NOTES.md
# for `-m "not sim"` and `-m "not slow"`).
test: lint
	$(BIN)/python -m pytest -q

clean:
	rm -rf $(VENV) *.egg-info
