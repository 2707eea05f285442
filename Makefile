# The two commands of the README:
#   make demo   -- set up .venv if needed, then run the main job (writes out/)
#   make test   -- set up .venv if needed, then run the test suite (two workers per CPU)
# and, by hand: make bench -- the timed benchmarks, checked against benchmarks/results/
# Both create or update the local virtual environment .venv; a second run installs nothing
# (the install step re-runs only when a requirements file or the package metadata changes).

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.landmark_nav-installed
DEPS := requirements.txt requirements-test.txt constraints.txt setup.py setup.cfg package.xml

.PHONY: demo test bench venv bags lint clean

venv: $(STAMP)

$(STAMP): $(DEPS)
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	@# pip byte-compiles every installed file one after the other (a third of the install's
	@# CPU); compileall does the same files afterwards on every CPU.
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --no-compile \
		-c constraints.txt -r requirements.txt -r requirements-test.txt
	@# A file that does not compile (pip would skip it too) is reported, not fatal.
	$(BIN)/python -m compileall -q -j 0 $$($(BIN)/python -c \
		'import sysconfig; print(*sorted({sysconfig.get_path(p) for p in ("purelib", "platlib")}))') \
		|| echo 'compileall: some installed files did not compile (they run from source)'
	@# setup.cfg sends scripts to lib/landmark_nav for `ros2 run`; in the venv they belong
	@# in bin, so the editable install overrides the develop script_dir.
	@printf '[develop]\nscript_dir=%s\n' "$(abspath $(BIN))" > $(VENV)/develop.cfg
	DIST_EXTRA_CONFIG=$(VENV)/develop.cfg $(BIN)/python -m pip install --quiet \
		--disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/landmark_nav demo --out out

# pytest-xdist, two workers per CPU: much of the suite waits on node processes and DDS,
# so a second worker per CPU fills those waits. A test file stays on one worker (its
# module fixtures, e.g. the golden runs, are computed once); files go out longest first
# (test/conftest.py orders them; --no-loadscope-reorder keeps that order). The real-time
# driver tests (wall-clock bounds on device I/O) run afterwards, apart: beside the workers
# on a busy machine they were starved of CPU. Their two files run side by side: their
# tests mostly wait on device timers (a quarter of a CPU each).
# Every worker collects every test file. Where the environment says not to write bytecode
# (PYTHONDONTWRITEBYTECODE), each worker would rewrite the asserts of every test module and
# compile the package from source at each run (8 of its 10 CPU-s of collection), and so
# would every node process a test starts: the test run writes its caches (__pycache__,
# ignored by git). On a fresh clone there are none yet: test/conftest.py writes them once,
# on every CPU, before the workers start (the four workers' collection 40 -> 17 CPU-s).
REALTIME_FILES := $(shell grep -l 'mark.realtime' test/test_*.py)
WORKERS ?= $(shell echo $$(( 2 * $$(nproc 2>/dev/null || echo 1) )))
WRITE_BYTECODE := PYTHONDONTWRITEBYTECODE=
# The parallel part's workers already fill the CPUs: one thread per numerical library each
# (BLAS threads spinning beside four workers cost CPU; the nodes default to one anyway).
ONE_THREAD := OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 OPENCV_FOR_THREADS_NUM=1

test: $(STAMP)
	$(WRITE_BYTECODE) $(ONE_THREAD) $(BIN)/python -m pytest -q -n $(WORKERS) --dist loadfile \
		--no-loadscope-reorder -m 'not realtime' test
	$(WRITE_BYTECODE) $(BIN)/python -m pytest -q -n 2 --dist loadfile -m realtime \
		$(REALTIME_FILES)

# Timing, soak and long evaluations: figures as ratios against an in-run reference,
# compared with the stored results (exit 1 on a regression). Run on an idle machine.
# The landmark rates and shuttle: the full samples of two unit tests, against stored bounds.
bench: $(STAMP)
	$(BIN)/python benchmarks/bench_soak.py
	$(BIN)/python benchmarks/bench_landmarks.py rates
	$(BIN)/python benchmarks/bench_landmarks.py shuttle

# Regenerate the committed recordings (fixed seeds) with the package's own simulator.
bags: $(STAMP)
	$(BIN)/landmark_nav simulate office --seed 1 --out bags/office --force
	$(BIN)/landmark_nav simulate hallway --seed 1 --out bags/hallway --force
	$(BIN)/landmark_nav simulate calibration --seed 1 --out bags/calibration --force
	$(BIN)/landmark_nav simulate corridor --seed 1 --out bags/corridor --force

clean:
	rm -rf $(VENV) out build install log
