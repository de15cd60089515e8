SHELL := /bin/bash
.DEFAULT_GOAL := test

PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python

# ROS 2 Jazzy from PyPI, pinned through the ros-jazzy-* names (the plain ros-* names also
# carry a newer distribution). [fastrtps] brings the only middleware published there.
ROS_WHEELS := \
	'ros-jazzy-rclpy[fastrtps]==7.1.6' \
	'ros-jazzy-std-msgs==5.3.6' \
	'ros-jazzy-geometry-msgs==5.3.6' \
	'ros-jazzy-visualization-msgs==5.3.6' \
	'ros-jazzy-diagnostic-msgs==5.3.6' \
	'ros-jazzy-std-srvs==5.3.6'

# Re-install only when the recipe or the package metadata changes.
HASH  := $(shell cat Makefile setup.py setup.cfg 2>/dev/null | sha256sum | cut -c1-16)
STAMP := $(VENV)/.installed-$(HASH)


.PHONY: venv demo test lint

venv: $(STAMP)

$(STAMP):
	@test -x $(PY) || $(PYTHON) -m venv $(VENV) || { \
	  echo "ensurepip is missing (Debian ships it in python3.11-venv): seeding pip from the system pip"; \
	  $(PYTHON) -m venv --without-pip $(VENV) && $(PYTHON) -m pip --python $(PY) install pip; }
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install --upgrade 'setuptools<80' wheel
	$(PY) -m pip install $(ROS_WHEELS)
	$(PY) -m pip install --no-build-isolation -e '.[test]' 'setuptools<80'
	@rm -f $(VENV)/.installed-*
	@touch $@

demo: venv
	$(VENV)/bin/cloth-mg demo

test: venv
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q test

lint: venv
	$(VENV)/bin/ruff check cloth_mg_ros test setup.py
