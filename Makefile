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
	'ros-jazzy-sensor-msgs==5.3.6' \
	'ros-jazzy-shape-msgs==5.3.6' \
	'ros-jazzy-diagnostic-msgs==5.3.6' \
	'ros-jazzy-std-srvs==5.3.6' \
	'ros-jazzy-rosgraph-msgs==2.0.3'

# Every install is pinned by constraints.txt (the versions the tests passed with); `make lock`
# refreshes it on purpose from the newest versions allowed here and in setup.py.
LOCK := constraints.txt

# Re-install only when the recipe, the package metadata or the pins change.
HASH  := $(shell cat Makefile setup.py setup.cfg $(LOCK) 2>/dev/null | sha256sum | cut -c1-16)
STAMP := $(VENV)/.installed-$(HASH)

# numba's on-disk cache of compiled kernels is stale once a source file changes (a pull: numba
# compares each file's time stamp and size): the warm-up fills it again after each install or
# change, so that the first run starts as fast as any later one (`cloth-mg warmup`, README).
SRC_HASH := $(shell find cloth_mg_ros -name '*.py' -printf '%p %T@ %s\n' 2>/dev/null \
	| sort | sha256sum | cut -c1-16)
WARM  := $(VENV)/.warm-$(HASH)-$(SRC_HASH)


.PHONY: venv warm demo test lint lock docs

venv: $(STAMP)

warm: $(WARM)

define make_venv
	@test -x $(1)/bin/python || $(PYTHON) -m venv $(1) || { \
	  echo "ensurepip is missing (Debian ships it in python3.11-venv): seeding pip from the system pip"; \
	  $(PYTHON) -m venv --without-pip $(1) && $(PYTHON) -m pip --python $(1)/bin/python install pip; }
endef

# $(call install,VENV,PIP OPTIONS): pip, setuptools, the ROS 2 wheels, this package and its tests.
define install
	$(1)/bin/python -m pip install $(2) --upgrade pip
	$(1)/bin/python -m pip install $(2) --upgrade 'setuptools<80' wheel
	$(1)/bin/python -m pip install $(2) $(ROS_WHEELS)
	$(1)/bin/python -m pip install $(2) --no-build-isolation -e '.[test,bench,cluster]' \
	  'setuptools<80'
endef

$(STAMP):
	$(call make_venv,$(VENV))
	$(call install,$(VENV),-c $(LOCK))
	@rm -f $(VENV)/.installed-*
	@touch $@

lock:
	rm -rf .venv-lock
	$(call make_venv,.venv-lock)
	$(call install,.venv-lock,)
	.venv-lock/bin/python -m pip install --no-build-isolation -e '.[peers]' 'setuptools<80'
	{ sed -n '/^#/p' $(LOCK); .venv-lock/bin/python -m pip freeze --all --exclude-editable \
	  | grep -v '^cloth'; } > $(LOCK).new && mv $(LOCK).new $(LOCK)
	rm -rf .venv-lock

# The docs extra (Sphinx, MyST) once per install, pinned like the rest.
DOCS := $(VENV)/.docs-$(HASH)

$(DOCS): $(STAMP)
	$(PY) -m pip install -c $(LOCK) --no-build-isolation -e '.[docs]' 'setuptools<80'
	@rm -f $(VENV)/.docs-*
	@touch $@

# The peers of `cloth-mg bench peers` (the .[peers] extra: Newton, Warp, MuJoCo, ~550 MB), for
# the test suite, whose tests run them (make demo does without); pinned like the rest. Warp
# compiles their kernels into its own cache once (`cloth-mg warmup --peers`, ~85 s on 2 cores).
PEERS := $(VENV)/.peers-$(HASH)

$(PEERS): $(STAMP)
	$(PY) -m pip install -c $(LOCK) --no-build-isolation -e '.[peers]' 'setuptools<80'
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/cloth-mg warmup --peers
	@rm -f $(VENV)/.peers-*
	@touch $@

# numba checks a cached kernel against its own file's time stamp only: a kernel that inlines
# a function from another module (stretch's from wrinkles) keeps stale code when only that
# module changed. So a source change (SRC_HASH) drops every cached kernel before warming up.
$(WARM): $(STAMP)
	@find cloth_mg_ros -name '*.nbi' -delete -o -name '*.nbc' -delete
	OPENBLAS_NUM_THREADS=1 $(VENV)/bin/cloth-mg warmup
	@rm -f $(VENV)/.warm-*
	@touch $@

demo: venv warm
	$(VENV)/bin/cloth-mg demo

# Two pytest workers (pytest-xdist): the node tests spend much of their time waiting on DDS
# and the other process, so two keep a 2-core machine busy (the suite: 777 s against 995 s
# on one). Whole files go to one worker (loadfile), so a module's fixtures (the dressing runs,
# the calibrations) are computed once.
TEST_WORKERS ?= 2
test: venv warm $(PEERS)
	$(VENV)/bin/ruff check cloth_mg_ros test setup.py launch doc
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile \
		-m "bench or not bench" --durations=25 test

# doc/: Sphinx with MyST pages, warnings as errors; the node's parameter table is generated
# from the code at each build (doc/conf.py). Output: doc/_build/html/index.html.
docs: $(DOCS)
	$(VENV)/bin/sphinx-build -W --keep-going -b html doc doc/_build/html

lint: venv
	$(VENV)/bin/ruff check cloth_mg_ros test setup.py launch doc
