# `make demo` and `make test` each set up .venv on a fresh machine first.
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.depthseg-installed

.PHONY: setup demo test lint bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml tools/setup.sh
	bash tools/setup.sh
	touch $(STAMP)

demo: setup
	$(PY) tools/demo.py

lint: setup
	$(VENV)/bin/ruff check .

test: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/python -m pytest -q

bench: setup
	$(VENV)/bin/depthseg-bench --threads 2

clean:
	rm -rf out .pytest_cache .ruff_cache
