# Two commands for a newcomer: `make run` and `make test`. Each creates .venv on first use.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-stamp
# pytest-xdist workers for `make test` (CI has 2 cores; the tests that start services draw ports per worker)
TEST_JOBS ?= 2

.PHONY: run test bench study feed antwerp app-figure clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

run: $(STAMP)
	sh scripts/system-deps.sh
	$(VENV)/bin/ecodrive serve

test: $(STAMP)
	sh scripts/system-deps.sh
	$(PY) -m pytest -q -n $(TEST_JOBS) --dist worksteal

study: $(STAMP)
	$(VENV)/bin/ecodrive study --out out/study

feed: $(STAMP)
	$(PY) -m spat_feed

antwerp: $(STAMP)  # the service on the Antwerp controller's recorded SPaT, through a real MQTT broker (docs/SPAT.md)
	sh scripts/system-deps.sh
	sh scripts/antwerp.sh

app-figure: $(STAMP)  # the README's and docs/APP.md's screenshots of the phone app (headless chromium)
	sh scripts/system-deps.sh
	ECODRIVE_APP_FIGURE=docs/figures/app_demo_drive.png $(PY) -m pytest -q tests/browser -k demo_drive
	ECODRIVE_APP_FIGURE_DIR=docs/figures $(PY) -m pytest -q tests/browser/test_countdown.py tests/browser/test_service_lost.py

bench: $(STAMP)
	for b in bench/bench_*.py; do $(PY) $$b || exit 1; done

clean:  # also numba's cached kernels: it keys each by its own file, not by the physics it inlines (docs/MODEL.md)
	rm -rf $(VENV) .pytest_cache build *.egg-info
	find . -path ./$(VENV) -prune -o -name '*.nb[ic]' -exec rm -f {} +
