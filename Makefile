# `make demo` and `make test` each set up .venv on a fresh machine first.
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.depthseg-installed

.PHONY: setup demo test test-slow lint bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml tools/setup.sh tools/constraints.txt
	bash tools/setup.sh
	touch $(STAMP)

demo: setup
	$(PY) tools/demo.py

lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/lint-imports

# `make test` skips the tests marked slow (each behaviour they check is also covered by a fast
# test); `make test-slow` runs only those.
test: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/lint-imports
	$(VENV)/bin/python -m pytest -q

test-slow: setup
	$(VENV)/bin/python -m pytest -q -m slow

bench: setup
	$(VENV)/bin/depthseg-bench --threads 2

clean:
	rm -rf out .pytest_cache .ruff_cache
