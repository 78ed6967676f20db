# Setup lives here: `make run` and `make test` work on a clean clone.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup run test test-long bench fmus trials train baseline docs clean chromium tbb bytecode lock

setup: $(STAMP)

# torch is pinned to the CPU build that pip finds on this machine's disk; pinning it
# before anything else keeps pip from resolving a CUDA build for a dependent.
# constraints.txt holds the versions the suite last passed with (`make lock` writes it): pyproject
# keeps lower bounds for users, while a fresh clone and CI install what was tested, not
# whatever pip resolves that day (a new mujoco or opencv major release).
$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip setuptools wheel
	$(PY) -m pip install --quiet -c constraints.txt "torch==2.13.0"
	$(PY) -m pip install --quiet -c constraints.txt -e ".[scenario,dashboard,models,parquet,ensemble,test,docs]"
	touch $(STAMP)

# Refresh constraints.txt from what .venv holds now (after `make test` passed on it). torch's
# local label (+cpu) is dropped: the pin names the release, the Makefile the build.
lock: $(STAMP)
	$(PY) -m pip freeze --exclude-editable --exclude hycosim | sed 's/+cpu$$//' | LC_ALL=C sort -f > constraints.txt

# Every run starts a process per node and one for the server, each importing the package. Where
# PYTHONDONTWRITEBYTECODE is set (as on these machines) each of them compiled its modules from
# source: 0.1 s of a process's 0.75 s of imports. Written here, they are read; a stale file is
# not (its source is newer), so this only ever costs the time to compile what changed.
bytecode: $(STAMP)
	$(PY) -m compileall -q -x "hycosim/scenario/build" hycosim benchmarks >/dev/null

# The whole scenario on loopback: one trial at 40° with the pretrained policy, camera
# correction, EthernetKRL export and the emulated controller; ends with the table and figure.
run: $(STAMP) bytecode
	$(VENV)/bin/hycosim trials --angles 40 --trials 1 -o runs/demo

# The paper's 80 trials, with and without camera correction (about 20 minutes one after the
# other); `make trials WORKERS=2` runs them on a local Dask cluster of two worker processes.
WORKERS ?=
TRIAL_FLAGS := --angles 30 40 50 60 --trials 20 $(if $(WORKERS),--workers $(WORKERS))
trials: $(STAMP) bytecode
	$(VENV)/bin/hycosim trials $(TRIAL_FLAGS) -o runs/trials
	$(VENV)/bin/hycosim trials $(TRIAL_FLAGS) --no-correction -o runs/trials-no-correction

# Train the policy from scratch (demonstrations, behaviour cloning, DDPG).
train: $(STAMP) bytecode
	$(VENV)/bin/hycosim train -o runs/train

# The paper's own formulation (DDPG from scratch) for the same training time, beside runs/train.
baseline: $(STAMP) bytecode
	$(PY) benchmarks/policy_baseline.py --minutes 20 --ours runs/train --plot runs/policy_baseline.png

# Two test processes, each taking whole files (a file's module fixtures are built once): most
# tests wait on processes and sockets, so on 2 cores the suite took 12.5–14 minutes instead of 19.
TEST_WORKERS ?= 2
test: $(STAMP) bytecode chromium tbb
	$(PY) -m pytest -q -p no:cacheprovider -n $(TEST_WORKERS) --dist loadfile --durations=25

# The dashboard's tests drive Debian's chromium through Playwright (no browser download).
chromium:
	@command -v chromium >/dev/null 2>&1 || { apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium; }

# ECOS, the reference engine of benchmarks/inprocess.py and its test, loads Debian's libtbb12.
tbb:
	@ldconfig -p | grep -q 'libtbb\.so\.12' || { apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends libtbb12; }

test-long: $(STAMP) bytecode
	$(PY) -m pytest -q -p no:cacheprovider -m long

bench: $(STAMP) bytecode chromium tbb
	$(PY) -m pip install --quiet -c constraints.txt -e ".[scenario,dashboard,models,parquet,ensemble,test,docs,bench]"
	$(PY) benchmarks/barrier.py --cpu --table benchmarks/results/barrier.md
	$(PY) benchmarks/inprocess.py --table benchmarks/results/inprocess.md
	$(PY) benchmarks/crosscheck.py --table benchmarks/results/crosscheck.md
	$(PY) benchmarks/fmu_overhead.py --table benchmarks/results/fmu_overhead.md
	$(PY) benchmarks/scene_fmus.py --table benchmarks/results/scene_fmus.md
	$(PY) benchmarks/memory.py --table benchmarks/results/memory.md
	$(PY) benchmarks/recording.py --table benchmarks/results/recording.md
	$(PY) benchmarks/decode.py --table benchmarks/results/decode.md
	$(PY) benchmarks/sweep.py --table benchmarks/results/sweep.md
	$(PY) benchmarks/trials.py --table benchmarks/results/trials.md
	$(PY) benchmarks/fuzz.py --table benchmarks/results/fuzz.md
	$(PY) benchmarks/status_flood.py --table benchmarks/results/status_flood.md
	$(PY) benchmarks/recovery.py --table benchmarks/results/recovery.md
	$(PY) benchmarks/accuracy.py --table benchmarks/results/accuracy.md --plot docs/images/accuracy.png
	$(PY) benchmarks/dashboard_cost.py --least-page --page-elsewhere --table benchmarks/results/dashboard_cost.md

# The manual as a site in site/ (make test builds it too, strictly, and runs its examples).
docs: $(STAMP)
	$(PY) -m mkdocs build --strict -d site

# The rod and robot-scene FMUs that the checkout's hycosim/scenario/configs/grasp-fmu.json uses.
fmus: $(STAMP) bytecode
	$(VENV)/bin/hycosim scene fmus -o hycosim/scenario/build/fmus

clean:
	rm -rf $(VENV) build site *.egg-info
