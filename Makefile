# nlcx developer commands. Everything runs in a local virtual environment (.venv),
# created and filled on first use, so a fresh clone needs only python3 (>= 3.10) and make.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.nlcx-installed
DEV_STAMP := $(VENV)/.nlcx-dev-installed
TUNING_STAMP := $(VENV)/.nlcx-tuning-installed
JOBS ?= 2
# make test and test-fast: JOBS pytest-xdist workers, a test file's tests on one worker (its
# module-scoped fixtures built once); a plain `python -m pytest tests/test_x.py` runs in one process
XDIST = -n $(JOBS) --dist loadfile

BASELINE_TABLES := table-2.3,table-2.5,table-3.2,table-3.7,table-4.2,table-4.4,table-5.1,table-5.8

.PHONY: install tuning-install dev-install run test test-fast lint screenshots reproduce reproduce-pendulums reproduce-cstr tables figures calibrate configs errata identify consistency \
	baseline baseline-diff baselines sweep-demo bench bench-gpu docs clean typecheck

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -e .
	# byte-compile nlcx as a regular install does (an editable one leaves it to the first import,
	# which cannot write it where PYTHONDONTWRITEBYTECODE is set)
	$(BIN)/python -m compileall -q nlcx
	# compile the main job's kernels into numba's disk cache and build matplotlib's font cache
	# now, so that the first nlcx run does not wait for them (a short run of the main job)
	rm -rf $(VENV)/warm-up  # the make file's own scratch run (an older nlcx's is unmarked)
	$(BIN)/nlcx run configs/xyz_error_ags.yaml simulation.t_end=0.1 --out $(VENV)/warm-up --no-report -q
	touch $(STAMP)

# the tuning extra (pymoo: the genetic algorithm), for the targets that tune, calibrate or identify
# with it (the thesis's GA-tuned results among them); make run does not wait for it
$(TUNING_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[tuning]"
	touch $(TUNING_STAMP)

# the test tools (pytest, ruff, sympy, scikit-fuzzy, Playwright) and the dask and tuning extras, for
# make test and the developer targets; make run does not wait for them
$(DEV_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,docs,dask,tuning]"
	touch $(DEV_STAMP) $(TUNING_STAMP)

## install: create .venv and install nlcx (make dev-install adds the test tools)
install: $(STAMP)

tuning-install: $(TUNING_STAMP)

dev-install: $(DEV_STAMP)

## run: the main job, the x-y-z pendulum under conventional vs error-AGS PID
run: install
	$(BIN)/nlcx run configs/xyz_error_ags.yaml

## test: the whole test suite, ruff included, on $(JOBS) pytest-xdist workers (what CI runs)
test: dev-install
	$(BIN)/python -m pytest -q $(XDIST)

## test-fast: the edit-test loop: every test but the slow, browser, gpu and notebook ones (a few minutes)
test-fast: dev-install
	$(BIN)/python -m pytest -q $(XDIST) -m "not slow and not browser and not gpu and not notebook"

## docs: build the documentation site into site/ (mkdocs, --strict; also a test)
docs: dev-install
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

## lint: ruff on the package, tests and scripts
lint: dev-install
	$(BIN)/ruff check nlcx tests scripts

## typecheck: mypy on the package (configured in pyproject.toml's [tool.mypy])
typecheck: dev-install
	$(BIN)/python -m mypy nlcx

## reproduce-pendulums: every figure and table of chapters 2-4, and claims.csv, in results/thesis/
reproduce-pendulums: tuning-install
	$(BIN)/nlcx reproduce --chapter 2 --chapter 3 --chapter 4 --jobs $(JOBS)

## reproduce-cstr: chapter 5 (the CSTR): figures, Table 5.8, tables 5.1-5.7, ZN variants, claims
reproduce-cstr: tuning-install
	$(BIN)/nlcx reproduce --chapter 5 --jobs $(JOBS) --out results/thesis

## reproduce: every figure and table of chapters 2-5 and all claims
reproduce: tuning-install
	$(BIN)/nlcx reproduce --jobs $(JOBS)

## screenshots: docs/img/report_*.png from results/thesis/report.html (after make reproduce; needs chromium)
screenshots: dev-install
	$(BIN)/python scripts/report_screenshots.py results/thesis/report.html docs/img

## tables / figures: every thesis table / figure (both come from one reproduce run)
tables figures: reproduce

## baseline: deliberately refresh the committed baseline tables (results/baseline/) after a reviewed change
baseline: tuning-install
	$(BIN)/nlcx reproduce --only $(BASELINE_TABLES) --profile literal --jobs $(JOBS) --out results/ci
	rm -rf results/baseline/tables && mkdir -p results/baseline && cp -r results/ci/tables results/baseline/

## baseline-diff: regenerate the baseline subset and diff it against results/baseline/ (also a test)
baseline-diff: tuning-install
	$(BIN)/nlcx reproduce --only $(BASELINE_TABLES) --profile literal --jobs $(JOBS) --out results/ci
	$(BIN)/nlcx diff results/baseline/tables results/ci/tables

## sweep-demo: the robustness sweep of configs/sweeps/ and its plot
sweep-demo: install
	$(BIN)/nlcx sweep configs/sweeps/robustness.yaml --jobs $(JOBS)
	$(BIN)/python scripts/plot_sweep.py results/robustness

## bench: the speed benchmarks (writes benchmarks/latest.txt)
bench: install
	$(BIN)/python benchmarks/run.py | tee benchmarks/latest.txt

## bench-gpu: nlcx on one CUDA GPU against a hand-written CUDA kernel (needs nlcx[cuda] and a GPU; writes
## benchmarks/gpu_latest.txt)
bench-gpu: install
	$(BIN)/pip install -q '.[cuda]'
	$(BIN)/python benchmarks/gpu.py | tee benchmarks/gpu_latest.txt

## identify: the identification studies and docs/fidelity.md (every number on it): fit every loop hypothesis on
## the train tables, reproduce under the literal and selected profiles, ask of each printed conventional column
## whether any loop gives it (each study resumes where it stopped; its wall time is in results/identify/*/study.json)
identify: tuning-install
	$(BIN)/nlcx identify configs/identify/pendulum_all.yaml --jobs $(JOBS) --out results/identify/pendulum_all
	$(BIN)/nlcx identify configs/identify/cstr.yaml --jobs $(JOBS) --out results/identify/cstr
	$(BIN)/nlcx identify configs/identify/final_round.yaml --jobs $(JOBS) --out results/identify/final_round
	$(BIN)/python scripts/fidelity_report.py profile results/identify > results/identify/selected.yaml
	cp results/identify/selected.yaml configs/thesis/profiles/selected.yaml
	$(BIN)/nlcx reproduce --profile literal --jobs $(JOBS) --out results/identify/reproduce_literal
	$(BIN)/nlcx reproduce --profile selected --jobs $(JOBS) --out results/identify/reproduce_selected
	$(BIN)/nlcx identify configs/identify/consistency.yaml --jobs $(JOBS) --out results/identify/consistency
	$(BIN)/nlcx linearize configs/x_error_ags.yaml --controller conventional --out results/identify/frozen_conventional
	$(BIN)/nlcx linearize configs/x_error_ags.yaml --controller proposed --along e --out results/identify/frozen_error_ags
	$(BIN)/nlcx linearize configs/x_time_ags.yaml --controller proposed --along t --out results/identify/frozen_time_ags
	$(BIN)/python scripts/fidelity_report.py doc results/identify > results/identify/fidelity.md
	cp results/identify/fidelity.md docs/fidelity.md
	$(BIN)/python scripts/fidelity_report.py replication results/identify > results/identify/replication.md
	cp results/identify/replication.md docs/replication.md
	cp results/identify/consistency/consistency.png docs/img/consistency.png
	cp results/identify/pendulum_all/ranking.png docs/img/identify_ranking.png

## consistency: the targeted search of the sets of printed cells the consistency study could not hit together
## (CMA-ES per set and hypothesis, every loop under the four definitions of t_r and t_s; capped at 61 sets, within
## an hour on 2 cores), then docs/fidelity.md again; needs `make identify`'s results
consistency: tuning-install
	$(BIN)/nlcx identify configs/identify/targeted.yaml --jobs $(JOBS) --out results/identify/targeted
	$(BIN)/python scripts/fidelity_report.py doc results/identify > results/identify/fidelity.md
	cp results/identify/fidelity.md docs/fidelity.md
	$(BIN)/python scripts/fidelity_report.py replication results/identify > results/identify/replication.md
	cp results/identify/replication.md docs/replication.md

## baselines: the four pendulums under conventional and AGS PID, LQR and sliding mode, in the thesis's
## scenarios and a robustness sweep (docs/baselines.md): results/baselines/ and its report
baselines: install
	$(BIN)/nlcx baselines --jobs $(JOBS) --out results/baselines

## calibrate: refit the unprinted conventional gains (writes configs/thesis/gains/conventional.yaml)
calibrate: tuning-install
	$(BIN)/nlcx calibrate configs/thesis/calibration/x_conventional.yaml --jobs $(JOBS) --write
	$(BIN)/nlcx calibrate configs/thesis/calibration/xz_z.yaml --jobs $(JOBS) --write

## configs: regenerate configs/thesis/ch*/fig_*.yaml from the figure list
configs: install
	$(BIN)/python scripts/make_thesis_configs.py

## errata: regenerate the derived models and docs/errata.md
errata: dev-install
	$(BIN)/python scripts/derive_pendulums.py
	$(BIN)/python scripts/errata.py

clean:
	rm -rf $(VENV) results/*/ .pytest_cache .ruff_cache
