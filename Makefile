# Two entry points (README): `make demo` runs the product, `make test` runs the test suite.
# Both set everything up first: Debian packages (scripts/install-system.sh) and a virtualenv.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test system setup lint bench

$(STAMP): pyproject.toml
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[all]'
	touch $(STAMP)

system:
	bash scripts/install-system.sh

setup: system $(STAMP)

demo: setup
	$(VENV)/bin/coach serve

test: setup lint
	PYOPENGL_PLATFORM=egl $(PY) -m pytest -q -p no:cacheprovider

# Lint and type-check (STYLE.md tooling); part of `make test`, so CI enforces both.
lint: setup
	$(VENV)/bin/ruff check engine app worker web tests benchmarks
	$(VENV)/bin/mypy
