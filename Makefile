# Development tasks for domplane_ros (GNU make). Everything runs in a local virtual environment,
# .venv, built from requirements.txt (ROS 2 Jazzy rclpy and messages come from PyPI wheels).
# A ROS install built with colcon does not need this file.

SHELL := /bin/bash
.DEFAULT_GOAL := test

PYTHON ?= python3
VENV := .venv
VPY := $(VENV)/bin/python
PYTEST_TIMEOUT_S ?= 300

# Keep DDS traffic on this machine and away from other runs: loopback discovery only, and a
# random domain per make invocation (test/conftest.py also gives its private contexts their
# own random domain).
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST
export ROS_DOMAIN_ID ?= $(shell echo $$(( RANDOM % 200 + 1 )))

.PHONY: venv test lint demo bench clean

venv: $(VENV)/.installed

# Third-party requirements: only when requirements.txt changes. pip byte-compiles what it
# installs on one core; compileall does it on every core (77 s -> 62 s for the whole step on
# this 2-core machine, measured 2026-12-02), and the .pyc files are still there for every run.
$(VENV)/.stamp: requirements.txt
	test -x $(VPY) || $(PYTHON) -m venv $(VENV)
	$(VPY) -m pip install --quiet --disable-pip-version-check --no-compile -r requirements.txt
	$(VPY) -m compileall -q -j 0 $(VENV)/lib
	touch $@

# The package itself, editable, so the console scripts in .venv/bin (plane_node, plane_replay)
# run the work tree's code. Editable installs skip data_files (ament index marker, share/,
# lib/domplane_ros launchers); test/test_install_tree.py checks those with a real install.
$(VENV)/.installed: $(VENV)/.stamp setup.py setup.cfg
	$(VPY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation \
		-e .
	touch $@

# The tests without DDS run on PYTEST_WORKERS processes (pytest-xdist, one file per worker at a
# time, so module fixtures are built once); then the ROS tests, also on PYTEST_WORKERS processes
# (each worker's private contexts on a DDS domain of its own, test/ros/conftest.py), except the
# `ros_timing` ones (test/ros/test_faults.py: a 100 Hz burst whose DDS losses, queues and
# latencies are measured, and the input rates of a camera drop-out), which run last, alone,
# because a busy second core would starve the delivery they measure. The ROS tests on two
# workers: 99 s -> 69 s of the run (measured 2026-12-03, 2-core VM).
PYTEST_WORKERS ?= 2

# glibc keeps the memory a test frees for its next arrays instead of returning it to the kernel
# and faulting it in again (a 640x480 render allocates ~100 MB of short-lived arrays): mmap only
# above 32 MB (glibc's largest threshold), trim only above 512 MB. Measured on ten rendered
# scenes and their cold pairs: page faults 150k -> 41k, system time 2.3 -> 1.3 s, rendering
# 10.4 -> 9.3 s, the whole 21.4 -> 19.8 s (2026-12-03, 2-core VM); the values computed are the same.
LESS_PAGE_FAULTS := MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=536870912 \
	MALLOC_TOP_PAD_=67108864

# Each worker computes on one thread (OpenBLAS and OpenCV would start a thread per core in
# each worker and spin for work the other worker's core is busy with: 18 % more CPU measured).
ONE_THREAD := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 OPENCV_FOR_THREADS_NUM=1

# Rendered scenes are cached on disk for the tests (domplane_ros/sim/render_cache.py): a scene
# several tests render is rendered once, also across the workers and the ROS run.
RENDER_CACHE := DOMPLANE_RENDER_CACHE=$(CURDIR)/.cache/render

# Byte-code is written for the test runs even where the environment says not to
# (PYTHONDONTWRITEBYTECODE=1 on this machine): the package's modules and pytest's rewritten test
# modules are then compiled once, not again by the ROS run (its collection 8.4 s -> 2.5 s) and
# by every plane_node and plane_replay process the tests start. The __pycache__ folders are
# ignored by git; `make clean` removes them.
WRITE_BYTECODE := PYTHONDONTWRITEBYTECODE=

# Every run always runs; the target fails if any failed.
test: venv
	status=0; \
	$(WRITE_BYTECODE) $(LESS_PAGE_FAULTS) $(RENDER_CACHE) $(ONE_THREAD) $(VPY) -m pytest -q --timeout=$(PYTEST_TIMEOUT_S) -n $(PYTEST_WORKERS) --dist loadfile \
		-m 'not ros' test || status=$$?; \
	$(WRITE_BYTECODE) $(LESS_PAGE_FAULTS) $(RENDER_CACHE) $(ONE_THREAD) $(VPY) -m pytest -q --timeout=$(PYTEST_TIMEOUT_S) -n $(PYTEST_WORKERS) --dist loadfile \
		-m 'ros and not ros_timing' test/ros || status=$$?; \
	$(WRITE_BYTECODE) $(LESS_PAGE_FAULTS) $(RENDER_CACHE) $(VPY) -m pytest -q --timeout=$(PYTEST_TIMEOUT_S) -m ros_timing test/ros || status=$$?; \
	exit $$status

lint: venv
	$(VPY) -m pytest -q --timeout=$(PYTEST_TIMEOUT_S) test/test_flake8.py test/test_pep257.py

demo: venv
	$(VPY) -m domplane_ros.tools.demo --output demo_output

bench: venv
	$(VPY) -m domplane_ros.tools.bench
	$(VPY) -m domplane_ros.tools.bench_pipeline

clean:
	rm -rf $(VENV) .cache domplane_ros.egg-info .pytest_cache .hypothesis demo_output \
		bench_output eval_output soak_output
	find domplane_ros test -name __pycache__ -type d -prune -exec rm -rf {} +
