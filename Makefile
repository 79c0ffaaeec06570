# The two commands of the README: `make demo` and `make test`. Both set everything up themselves.
VENV  ?= .venv
PY    := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test quick bench calibration-table setup clean runs results cli-docs
setup: $(STAMP)

$(STAMP): pyproject.toml scripts/bootstrap.sh
	VENV=$(VENV) bash scripts/bootstrap.sh
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/lft demo --out out/demo

quick: $(STAMP)
	$(VENV)/bin/lft demo --quick --out out/quick

bench: $(STAMP)
	$(VENV)/bin/lft bench --json out/bench.json $$( [ -f out/demo/calibration.json ] && echo --calibration out/demo/calibration.json )

calibration-table: $(STAMP)
	$(VENV)/bin/lft calibrate seeds --seeds 1,2,3,4,5 --out out/calibration

test: $(STAMP)
	$(VENV)/bin/lint-imports
	$(PY) -m pytest -q tests

# Measured results: `make runs` runs the commands behind docs/results.md (the lft commands a user types) and
# stores their JSON with provenance in docs/runs/ (hours on 2 cores for all of them; RUNS="--quick" for the
# quarter-resolution ones, RUNS="demo bench" for some); `make results` rewrites docs/results.md and docs/cli.md.
RUNS ?=
runs: $(STAMP)
	$(PY) scripts/store_runs.py $(RUNS)

results: $(STAMP) cli-docs
	$(PY) -m lftransfer.app.results docs/runs docs/results.md

# docs/cli.md: typer's own generator (`typer lftransfer.app.cli utils docs --name lft`). The module is imported
# first because cli.py and twin_cli.py import each other, which fails when typer loads cli.py afresh on its own.
cli-docs: $(STAMP)
	$(PY) -c "import sys, lftransfer.app.cli; from typer.cli import main; sys.argv = ['typer', 'lftransfer.app.cli', 'utils', 'docs', '--name', 'lft', '--output', 'docs/cli.md']; main()"

clean:
	rm -rf out .pytest_cache
