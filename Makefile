# The two commands of the README: `make demo` and `make test`. Both set everything up themselves.
VENV  ?= .venv
PY    := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test quick bench calibration-table setup clean
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

clean:
	rm -rf out .pytest_cache
