# The two commands of the README: `make demo` (main job) and `make test`.
PY := .venv/bin/python
OUT ?= out

.PHONY: setup demo test bench clean

setup:
	@bash scripts/setup.sh

demo: setup
	$(PY) -m harness.cli demo -o $(OUT)

test: setup
	$(PY) -m pytest

bench: setup
	$(PY) benchmarks/run_all.py

clean:
	rm -rf $(OUT)
