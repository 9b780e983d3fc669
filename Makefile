# One-command set-up: `make demo` (main job) and `make test` (tests) create .venv on first use.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# pytest-xdist workers (2: CI's cores; `make test TEST_WORKERS=auto` uses every core this machine shows)
TEST_WORKERS ?= 2
# Keep DDS discovery on this machine; tests set their own ROS_DOMAIN_ID per process.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: venv test demo bench clean

venv: $(STAMP)

$(STAMP): requirements.txt setup.py setup.cfg $(wildcard */__init__.py)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	touch $(STAMP)

test: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/mypy
	$(PY) -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) --dist loadfile --durations=10 test

demo: $(STAMP)
	$(VENV)/bin/noise-monitor replay bags/ev76c661_field.mcap --profile ev76c661 --out out/demo --json out/demo/summary.json

bench: $(STAMP)
	$(PY) bench/run_all.py

clean:
	rm -rf $(VENV) out build install log
