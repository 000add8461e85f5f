# The commands of the README: `make demo` (main job), `make test` and `make lint`.
PY := .venv/bin/python
OUT ?= out

.PHONY: setup demo test lint bench clean

setup:
	@bash scripts/setup.sh

demo: setup
	$(PY) -m harness.cli demo -o $(OUT)

test: setup
	$(PY) -m pytest

lint: setup
	.venv/bin/ruff check .

bench: setup
	$(PY) benchmarks/run_all.py

clean:
	rm -rf $(OUT)
