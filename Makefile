# humanoid_planner: one-command setup, tests and demo on a machine without a ROS install.
#
#   make test    set up .venv (first time only), then lint (ruff) and run the whole test suite
#   make run     start the planner node (Ctrl-C stops it)
#   make demo    start the node in its own process, plan a single- and a dual-arm grasp, print a
#                table, write pictures to out/
#   make setup   only the setup: .venv with pinned deps + interface package + this package
#   make clean   remove .venv and build/
#   make bench   planner benchmark and the clients row (benchmarks/README.md); make bench-quick: its CI smoke version
#   make bench-mbm MBM_DIR=...   the public MotionBenchMaker problems (Panda, Fetch), GIRRT beside the OMPL peer
#   make mplib-venv   .venv-mplib for the MPlib peer (bench_mbm.py --planners girrt,ompl,mplib); not part of setup
#   make sweep   conformance sweep over example-robot-data's robots with arms (out/sweep/; about an hour)
#
# Setup is tracked by stamp files inside .venv, so a second run on a set-up machine is a no-op.
# On a real ROS 2 Jazzy install use colcon instead (see README.md).

SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
.DEFAULT_GOAL := test

# The ROS 2 Jazzy wheels are built for CPython 3.11: prefer python3.11 when it exists.
PYTHON ?= $(shell command -v python3.11 2>/dev/null || echo python3)
VENV := .venv
VPY := $(abspath $(VENV))/bin/python
BUILD := build
STAMP_DEPS := $(VENV)/.stamp-deps
STAMP_MSGS := $(VENV)/.stamp-msgs
NODE_EXE := $(VENV)/bin/planner_node
STAMP_AMENT := $(VENV)/.stamp-ament
EXECUTABLES := planner_node grasp_client planner_demo
MSG_SRCS := $(shell find msg_defs -type f 2>/dev/null)
PARAMS := config/planner.yaml
PYTEST_ARGS ?=
PYTEST_WORKERS ?= 2
# pytest-xdist processes of make test (each its own ROS domain); 0 runs the suite in this process
ROBOT ?= armar3
# make run's robot preset; `make run ROBOT=` waits for the robot_description topics instead

# The ROS wheels' bootstrapper (.pth) re-executes Python once with LD_LIBRARY_PATH set and marks
# the environment as done; never inherit that mark from another venv's process.
unexport _ROS_WHEELS_BOOTSTRAP_COMPLETE

.PHONY: setup test run demo clean

setup: $(STAMP_AMENT)

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)

# Pinned runtime/test dependencies; then point the wheels' exported CMake files at this venv's
# Python headers and numpy (they name the wheel builder's /opt/python/cp311-cp311 paths).
# uv installs the same pinned set in parallel (measured on a fresh venv: 22 s against pip's 59 s, both compiling bytecode);
# plain pip is the fallback when uv cannot be had.
UV_VERSION := 0.13.8
$(STAMP_DEPS): requirements.txt | $(VENV)/bin/python
	mkdir -p $(BUILD)
	@echo "install -r requirements.txt (uv, else pip; log: $(BUILD)/pip-install.log)"
	@{ $(VPY) -m pip install --disable-pip-version-check -q uv==$(UV_VERSION) \
	    && $(VPY) -m uv pip install --compile-bytecode --python $(VPY) -r requirements.txt; } > $(BUILD)/pip-install.log 2>&1 \
	  || $(VPY) -m pip install --disable-pip-version-check -r requirements.txt >> $(BUILD)/pip-install.log 2>&1 \
	  || { tail -n 40 $(BUILD)/pip-install.log; exit 1; }
	py_inc=$$($(VPY) -c 'import sysconfig; print(sysconfig.get_paths()["include"])'); \
	np_inc=$$($(VPY) -c 'import numpy; print(numpy.get_include())'); \
	{ grep -rlZ --include='*.cmake' /opt/python/cp311-cp311 $(VENV)/share || true; } | xargs -0 -r sed -i \
	  -e "s|/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include|$$np_inc|g" \
	  -e "s|/opt/python/cp311-cp311/include/python3.11|$$py_inc|g"
	touch $@

# The interface package humanoid_planner_interfaces (msg_defs/), built with the real rosidl
# pipeline and installed into the venv (its Python module lands in site-packages).
$(STAMP_MSGS): $(STAMP_DEPS) $(MSG_SRCS)
	mkdir -p $(BUILD)
	AMENT_PREFIX_PATH=$(abspath $(VENV)) PATH=$(abspath $(VENV))/bin:$$PATH cmake -S msg_defs -B $(BUILD)/msg_defs \
	  -DCMAKE_PREFIX_PATH=$(abspath $(VENV)) -DCMAKE_INSTALL_PREFIX=$(abspath $(VENV)) \
	  -DPython3_EXECUTABLE=$(VPY) -DBUILD_TESTING=OFF -Wno-dev > $(BUILD)/msg_defs.log 2>&1 \
	  || { cat $(BUILD)/msg_defs.log; exit 1; }
	PATH=$(abspath $(VENV))/bin:$$PATH $(MAKE) --no-print-directory -C $(BUILD)/msg_defs -j2 install \
	  >> $(BUILD)/msg_defs.log 2>&1 || { tail -n 60 $(BUILD)/msg_defs.log; exit 1; }
	$(VPY) -c 'from humanoid_planner_interfaces.srv import GetPlanningScene; print("built", GetPlanningScene.__module__)'
	touch $@

# This package, editable (source edits are live), with the console script .venv/bin/planner_node.
# --use-pep517: without it pip falls back to `setup.py develop`, which follows setup.cfg's [develop]
# script_dir (lib/humanoid_planner, the ROS layout used by colcon) instead of .venv/bin.
$(NODE_EXE): $(STAMP_MSGS) setup.py setup.cfg package.xml
	$(VPY) -m pip install --disable-pip-version-check -q --no-deps --no-build-isolation --use-pep517 -e .
	test -x $@
	touch $@

# The layout of a ROS install space inside the venv, so that with AMENT_PREFIX_PATH=.venv
# `ros2 run humanoid_planner planner_node` and ament_index find this package as in a colcon install:
# the package marker in the ament index, share/humanoid_planner/{package.xml,config} (links to the
# sources) and lib/humanoid_planner/<executable> (links to the console scripts in .venv/bin).
$(STAMP_AMENT): $(NODE_EXE) resource/humanoid_planner
	mkdir -p $(VENV)/share/ament_index/resource_index/packages $(VENV)/share/humanoid_planner $(VENV)/lib/humanoid_planner
	cp resource/humanoid_planner $(VENV)/share/ament_index/resource_index/packages/humanoid_planner
	ln -sfn $(abspath package.xml) $(VENV)/share/humanoid_planner/package.xml
	ln -sfn $(abspath config) $(VENV)/share/humanoid_planner/config
	for exe in $(EXECUTABLES); do ln -sfn ../../bin/$$exe $(VENV)/lib/humanoid_planner/$$exe; done
	touch $@

# The numba kernels (the collision checker's, the search trees', the IK's) compiled into their cache first (~7 s once, then ~0.5 s), so
# that no test's node or worker process compiles them inside a deadline.
test: $(STAMP_AMENT)
	$(VPY) -m ruff check .
	$(VPY) -m humanoid_planner.core.compiled
	$(VPY) -m pytest -q test -n $(PYTEST_WORKERS) $(PYTEST_ARGS)

run: $(STAMP_AMENT)
	$(VENV)/bin/planner_node --ros-args --params-file $(PARAMS) $(if $(ROBOT),-p robot:=$(ROBOT))

demo: $(STAMP_AMENT)
	$(VPY) -m humanoid_planner.demo --params-file $(PARAMS) --out out

clean:
	rm -rf $(VENV) $(BUILD)

# Benchmarks (benchmarks/README.md): planners vs the OMPL peer, DAGRRT speed-up, plan_grasp service
# overhead; then plan_to_state and plan_place beside the OMPL peer, and get_planning_scene reads. Results in out/bench/ (results.json, table.md, bench.png). Extra arguments: BENCH_ARGS,
# e.g. make bench BENCH_ARGS="--robots armar3 --families boxes6 --planners girrt,ompl".
BENCH_ARGS ?=
.PHONY: bench bench-quick bench-clients bench-mbm mplib-venv soak sweep

# Reliability soak (test/soak.py, docs/RELIABILITY.md): a dual_arm node under a busy robot's load for
# --duration s (default 600; RSS slopes of the node and its arm process, every answer and plan checked;
# out/soak/), >= 5000 fuzzed scene messages against the reference model, the hostile-load acceptance.
# About 15 minutes. The hour alone: make soak SOAK_ARGS="--skip fuzz,load --duration 3600".
SOAK_ARGS ?=
soak: $(NODE_EXE)
	$(VPY) test/soak.py $(SOAK_ARGS)

bench: $(STAMP_AMENT)
	$(VPY) benchmarks/bench_planners.py $(BENCH_ARGS)
	$(VPY) benchmarks/bench_to_state.py
	$(VPY) benchmarks/bench_place.py
	$(VPY) benchmarks/bench_scene_reads.py
	$(VPY) benchmarks/bench_clients.py

# Plans/s with 1, 2, 4, 8 clients through ROS, worker processes vs threads, and the hand-off cost (about 4 min)
bench-clients: $(STAMP_AMENT)
	$(VPY) benchmarks/bench_clients.py --check

# MotionBenchMaker (benchmarks/README.md): MBM_DIR holds one folder per robot (<robot>/<robot>.urdf, .srdf, meshes/,
# problems/<family>_<robot>/); GIRRT and the OMPL peer on the first MBM_PROBLEMS problems of each family, every plan
# verified. Results in out/bench/ (mbm.json, mbm.md). Extra arguments: MBM_ARGS, e.g. MBM_ARGS="--families box,cage";
# MBM_ARGS="--planners girrt,ompl,mplib" adds MPlib (make mplib-venv first).
MBM_DIR ?=
MBM_ROBOTS ?= panda fetch
MBM_PROBLEMS ?= 10
MBM_BUDGET ?= 10
MBM_ARGS ?=
bench-mbm: $(STAMP_AMENT)
	@test -n "$(MBM_DIR)" || { echo "make bench-mbm MBM_DIR=<folder with $(MBM_ROBOTS) (MotionBenchMaker's robots and problems)>"; exit 2; }
	$(VPY) benchmarks/bench_mbm.py $(foreach r,$(MBM_ROBOTS),--robot-dir $(MBM_DIR)/$(r)) \
	  --problems $(MBM_PROBLEMS) --budget $(MBM_BUDGET) $(MBM_ARGS)

# MPlib 0.2.1 (the MotionBenchMaker peer, benchmarks/mplib_peer.py) needs numpy < 2; the project's venv has numpy 2,
# so MPlib gets a venv of its own, driven as a subprocess. Only for the benchmark: setup and test never need it.
MPLIB_VENV := .venv-mplib
MPLIB_PYTHON ?= $(shell command -v python3.11 2>/dev/null || echo python3)
mplib-venv: $(MPLIB_VENV)/.stamp-mplib

$(MPLIB_VENV)/.stamp-mplib:
	$(MPLIB_PYTHON) -m venv $(MPLIB_VENV)
	$(MPLIB_VENV)/bin/python -m pip install --disable-pip-version-check -q mplib==0.2.1 "numpy<2"
	$(MPLIB_VENV)/bin/python -c 'import mplib; print("mplib", mplib.__version__, "in $(MPLIB_VENV)")'
	touch $@

bench-quick: $(STAMP_AMENT)
	$(VPY) benchmarks/bench_planners.py --quick $(BENCH_ARGS)
	$(VPY) benchmarks/bench_to_state.py --robots armar3 --problems 3
	$(VPY) benchmarks/bench_place.py --problems 3

# Conformance sweep (scripts/robot_sweep.py): every robot with arms in example-robot-data, generated problems
# proven solvable by a plain RRT-Connect, GIRRT / DAGRRT at 10 s, every plan verified. Results in out/sweep/
# (results.json, table.md). Extra arguments: SWEEP_ARGS, e.g. make sweep SWEEP_ARGS="--robots panda,talos --problems 3".
SWEEP_ARGS ?=
sweep: $(STAMP_AMENT)
	$(VPY) scripts/robot_sweep.py $(SWEEP_ARGS)
