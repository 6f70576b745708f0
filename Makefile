# The README's two set-up commands: `make demo` (main job on defaults) and `make test`.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin

.PHONY: bench-explain demo test wheel wheel-test lint rust-test py-test bench install install-test bench-fast-path bench-load bench-requirements bench-irsim bench-faults bench-shrink bench-search bench-coverage bench-profiles bench-vo bench-ros2-start bench-gym bench-stage bench-scale bench-weights profile stage

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

install: $(BIN)/python
	$(BIN)/pip install -q .

# The ROS 2 extra where its wheels install (they skip with a reason where they do not), and
# the JUnit schema CI servers use (junit-10.xsd, MIT, which pytest's source release carries)
# for the JUnit tests. The extension is built by the venv's own maturin (no build isolation),
# so that `make wheel` after it finds everything compiled.
# Without isolation an sdist among the extras' dependencies (empy, which the rosidl generators
# use) is built with the venv's setuptools, and Python 3.11's venv carries one too old to make
# a wheel: without these the ROS 2 extra fails to install wherever pip has no wheel of it cached.
install-test: $(BIN)/python
	$(BIN)/pip install -q 'maturin>=1.7,<2' 'setuptools>=70.1' wheel
	PATH="$(abspath $(BIN)):$$PATH" $(BIN)/pip install -q --no-build-isolation -e '.[test,ros2,navground]' \
		|| PATH="$(abspath $(BIN)):$$PATH" $(BIN)/pip install -q --no-build-isolation -e '.[test,navground]' \
		|| PATH="$(abspath $(BIN)):$$PATH" $(BIN)/pip install -q --no-build-isolation -e '.[test]'
	$(MAKE) -s test-artifacts/junit-10.xsd || echo "warning: no JUnit schema; its tests will skip" >&2

test-artifacts/junit-10.xsd:
	mkdir -p test-artifacts/pytest-sdist
	$(BIN)/pip download -q --no-deps --no-binary :all: -d test-artifacts/pytest-sdist "pytest==$$($(BIN)/python -c 'import pytest; print(pytest.__version__)')"
	tar -xzf test-artifacts/pytest-sdist/pytest-*.tar.gz -O --wildcards '*/testing/example_scripts/junit-10.xsd' > $@.part
	mv $@.part $@

demo: install
	$(BIN)/sitgen demo -o demo

# Clippy in the release profile: its build scripts and proc macros are the ones the install
# compiled (the dev profile's, optimised for a developer's tests, would be built again): about
# 40 s after `make install-test` instead of 130-220 s. It reads pyo3's configuration from the
# file maturin wrote, as maturin's builds do: without it pyo3's build scripts run again, and
# `make wheel` then compiles pyo3, numpy and the extension again (20-45 s).
lint:
	cargo fmt --all --check
	config="$$(ls "$(CURDIR)"/target/maturin/pyo3-config-*.txt 2>/dev/null | head -n 1)"; \
		$${config:+env PYO3_CONFIG_FILE="$$config"} cargo clippy --release --workspace --all-targets -- -D warnings
	$(BIN)/ruff check python tests benches examples
	$(BIN)/ruff format --check python tests benches examples
	$(BIN)/mypy
	$(BIN)/lint-imports pyproject.toml

# In the release profile, whose dependencies the install has already compiled: a clean
# `make test` spends 2 minutes on the test build instead of about 6 (Cargo.toml's test profile
# is for a developer's own `cargo test`).
rust-test:
	cargo test --release -p sitgen-core

# A process a core (up to four) shares out the suite a test file each, the ROS 2 tests among
# them: a node's run is handed its inputs in order and waited on, so a loaded machine changes
# no result (test_ros2_styles.py keeps every core busy on purpose).
py-test:
	$(BIN)/pytest -n auto --maxprocesses 4 --dist loadfile

test: install-test lint rust-test py-test wheel-test

# A wheel for Python 3.11 and later (abi3), which installs where there is no Rust toolchain.
wheel: $(BIN)/python
	$(BIN)/pip install -q 'maturin>=1.7,<2'
	rm -f dist/sitgen-*.whl
	PATH="$(abspath $(BIN)):$$PATH" $(BIN)/maturin build --release --out dist

# The wheel as a user without Rust gets it: a fresh virtual environment, no cargo or rustc on
# PATH, `pip install` of the wheel, then `sitgen demo` (100 situations) in an empty folder.
WHEEL_VENV := target/wheel-test
wheel-test: wheel
	rm -rf $(WHEEL_VENV) && $(PYTHON) -m venv $(WHEEL_VENV)
	PATH="$$(echo "$$PATH" | tr ':' '\n' | grep -v -e cargo -e rustup | paste -sd:)" sh -c '\
		! command -v cargo && ! command -v rustc && \
		$(WHEEL_VENV)/bin/pip install -q dist/sitgen-*-abi3-*.whl && \
		rm -rf $(WHEEL_VENV)/demo && mkdir $(WHEEL_VENV)/demo && cd $(WHEEL_VENV)/demo && \
		../bin/sitgen demo -o demo --n 100'

bench: install-test
	$(BIN)/python benches/run.py

# Robust kill rate of snd_follow's seeded faults (first and harder) and the equivalent mutants'
# false kills, random generation at 50-500 situations over 5 seeds (about 20 minutes on 2 cores).
bench-faults: install-test
	$(BIN)/python benches/faults.py

bench-shrink: install-test
	$(BIN)/python benches/shrink.py

# MAP-Elites search against random generation at budgets 250 and 500 over 5 seeds (about 10
# minutes on 2 cores).
bench-search: install-test
	$(BIN)/python benches/search.py

# Learned weights: Kendall tau of weights fitted to 20, 50 and 200 judgements of a synthetic
# expert, informative pairs against random ones (docs/weights.md).
bench-weights: install-test
	$(BIN)/python benches/weights.py

# Coverage-guided search against random generation at budgets 100, 250 and 500 over 5 seeds:
# cells covered and the seeded faults' kill rate (about 15 minutes on 2 cores).
bench-coverage: install-test
	$(BIN)/python benches/situation_coverage.py

# The default campaign under the default and paper run profiles, beside the paper's score
# distribution, over 3 seeds (about 4 minutes on 2 cores).
bench-profiles: install-test
	$(BIN)/python benches/profiles.py

# A vo agent among vo peers against the same among blind peers: oscillations, reciprocal ones,
# collisions; draws docs/vo-*.png (about 3 minutes on 2 cores).
bench-vo: install-test
	$(BIN)/python benches/vo_reciprocal.py

# A ROS 2 node's start-up beside busy cores, in sitgen's session and in a session of its own
# (scheduler autogroups; docs/ros2.md, "Timing and determinism"; about 10 minutes on 2 cores).
bench-ros2-start: install-test
	$(BIN)/python benches/ros2_start.py

# What a python: class on the fast path costs: the trivial class's row of `make bench` and a
# 200-run campaign's wall time (benches/fast_path.py; about 40 s on 2 cores).
bench-fast-path: install-test
	$(BIN)/python benches/fast_path.py

# A slow controller's steps on a loaded machine, and what robustness copies add to the default
# campaign on seeds 0-4 (benches/load.py; an idle machine, a few minutes).
bench-load: install-test
	$(BIN)/python benches/load.py

# What judging five requirements adds to the default campaign's processor time (two pairs,
# one worker; docs/requirements.md).
bench-requirements: install-test
	$(BIN)/python benches/requirement_cost.py

# Where a step's time goes: the reference scene without Python under perf (Linux perf needed).
profile:
	cargo build --release -q -p sitgen-core --example reference_scene
	perf record -F 2000 -g -o target/perf.data target/release/examples/reference_scene 10 runs
	perf report -i target/perf.data --no-children --sort symbol --stdio 2>/dev/null \
		| grep -E '^ +[0-9]' | head -30

# 100,000 runs of the paper's campaign (60 s limit) through Ray on this machine: runs/s, memory
# over the campaign, store bytes per run without trajectories (about 40 minutes on 2 cores).
bench-scale: install-test
	$(BIN)/python benches/scale.py

# Environment steps per second of sitgen.controllers.gym, one world and vectorised (about 2 minutes).
bench-gym: install-test
	$(BIN)/python benches/gym_env.py

# IR-SIM is not a dependency of sitgen: the comparison gets a virtual environment of its own,
# with ir-sim and sitgen built from this tree (again on each run, so it measures the tree).
IRSIM_VENV := benches/.venv-irsim

$(IRSIM_VENV)/bin/python:
	$(PYTHON) -m venv $(IRSIM_VENV)
	$(IRSIM_VENV)/bin/python -m pip install -q --upgrade pip

bench-irsim: $(IRSIM_VENV)/bin/python
	$(IRSIM_VENV)/bin/pip install -q 'ir-sim>=2.12,<3' .
	$(IRSIM_VENV)/bin/python benches/irsim_compare.py

# Stage 4.3 from ../shared/tools/stage and the sitgen_stage plugin, into target/stage (about 3
# minutes; installs the Debian packages Stage's build needs). The cross-check tests use it.
stage:
	bash integrations/stage/build.sh

# The Stage cross-check on every preset (two situations each, 30 s): the figures of
# docs/stage.md (about 30 s after `make stage`).
bench-stage: install-test
	$(BIN)/python benches/stage_crosscheck.py

bench-explain: install-test
	$(BIN)/python benches/explain_cost.py
