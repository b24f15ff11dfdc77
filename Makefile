# nlcx developer commands. Everything runs in a local virtual environment (.venv),
# created and filled on first use, so a fresh clone needs only python3 (>= 3.10) and make.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.nlcx-installed

.PHONY: install run test lint clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

## install: create .venv and install nlcx with its test tools
install: $(STAMP)

## run: the main job, the chapter-2 x pendulum experiments (time- and error-AGS)
run: install
	$(BIN)/nlcx run configs/x_time_ags.yaml
	$(BIN)/nlcx run configs/x_error_ags.yaml

## test: the whole test suite, ruff included (what CI runs)
test: install
	$(BIN)/python -m pytest -q

## lint: ruff on the package, tests and scripts
lint: install
	$(BIN)/ruff check nlcx tests

clean:
	rm -rf $(VENV) results/*/ .pytest_cache .ruff_cache
