# The two commands of the README: `make demo` and `make test`.
# Both create .venv and install the package with its pinned lower bounds first.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
DEMO ?= approach_rtk20
# the IMU grade preset of the demo flight (companion --grade): mems for the MEMS-grade fixtures
DEMO_GRADE ?= tactical
# an optional TOML file whose keys override the grade's
DEMO_CONFIG ?=

.PHONY: setup demo test lint bench clean

setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,plot,console,batch]'
	touch $@

demo: setup
	mkdir -p out
	$(BIN)/companion replay sitl_fixtures/$(DEMO).tlog --output out/$(DEMO).out.tlog --grade $(DEMO_GRADE) $(if $(DEMO_CONFIG),--config $(DEMO_CONFIG))
	$(BIN)/companion evaluate out/$(DEMO).out.tlog --truth sitl_fixtures/$(DEMO).truth.csv --plot out/$(DEMO).png

lint: setup
	$(BIN)/ruff check companion tests bench
	$(BIN)/mypy

test: lint
	$(BIN)/python -m pytest -q

bench: setup
	$(BIN)/python bench/throughput.py

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache
