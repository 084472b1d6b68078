# Two commands on a fresh machine: `make demo` (the main job, on the embedded local server) and
# `make test` (the whole suite). Both create or reuse .venv (Python 3.12, the version the lock
# file was tested on) and install the pinned dependency set of constraints.txt.

PYTHON_VERSION := 3.12
PYENV_ROOT ?= $(HOME)/.pyenv
IS_PYTHON_VERSION := import sys; sys.exit("%d.%d" % sys.version_info[:2] != "$(PYTHON_VERSION)")
# The first interpreter that really is $(PYTHON_VERSION): python3.12 on PATH (a pyenv shim only
# counts when it runs), the newest pyenv-installed 3.12.x, then python3. `make PYTHON=...` wins.
ifndef PYTHON
PYTHON := $(shell for python in python$(PYTHON_VERSION) \
	$$(ls -1d $(PYENV_ROOT)/versions/$(PYTHON_VERSION).*/bin/python 2>/dev/null | sort -rV) \
	python3; do "$$python" -c '$(IS_PYTHON_VERSION)' 2>/dev/null && { command -v "$$python"; break; }; done)
endif
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
EXTRAS := dev,docs,lerobot,rerun,depth,ray
# The LeRobot plugins, each a small distribution LeRobot finds by name (lerobot_policy_oasis,
# lerobot_robot_oasis, lerobot_teleoperator_oasis, lerobot_env_oasis).
PLUGINS := policies robots teleoperators envs
DEMO_OUT ?= outputs/demo

define NO_PYTHON
No Python $(PYTHON_VERSION) found (looked for python$(PYTHON_VERSION) on PATH and
$(PYENV_ROOT)/versions/$(PYTHON_VERSION).*). Install one, then run make again:
  pyenv:          pyenv install $(PYTHON_VERSION)
  Ubuntu 24.04:   sudo apt-get install python$(PYTHON_VERSION) python$(PYTHON_VERSION)-venv
  macOS:          brew install python@$(PYTHON_VERSION)
or point at one: make PYTHON=/path/to/python$(PYTHON_VERSION) ...
endef
export NO_PYTHON

.PHONY: demo test docs lint protos lock bench bench-learning bench-crop-rule bench-ray-nodes bench-viewer \
	ffmpeg-libs clean-venv venv-python

venv-python:
	@if [ -x $(PY) ] && ! $(PY) -c '$(IS_PYTHON_VERSION)'; then \
		echo "$(VENV) is not Python $(PYTHON_VERSION) (the lock file's): recreating it"; \
		rm -rf $(VENV); \
	fi
	@if [ ! -x $(PY) ]; then \
		if [ -z "$(PYTHON)" ]; then echo "$$NO_PYTHON" >&2; exit 1; fi; \
		if ! "$(PYTHON)" -c '$(IS_PYTHON_VERSION)' 2>/dev/null; then \
			echo "PYTHON=$(PYTHON) is not a working Python $(PYTHON_VERSION)" >&2; exit 1; \
		fi; \
		echo "creating $(VENV) with $(PYTHON)"; \
		"$(PYTHON)" -m venv $(VENV); \
	fi

$(STAMP): pyproject.toml $(PLUGINS:%=%/pyproject.toml) constraints.txt | venv-python
	$(PY) -m pip install --quiet --upgrade "pip>=24"
	$(PY) -m pip install --quiet -c constraints.txt -e ".[$(EXTRAS)]"
	$(PY) -m pip install --quiet -c constraints.txt --no-deps $(PLUGINS:%=-e %/)
	touch $(STAMP)

demo: venv-python $(STAMP)
	$(PY) -m oasis_torchrl demo output_dir=$(DEMO_OUT)

test: venv-python $(STAMP)
	$(VENV)/bin/ruff check .
	$(PY) -m pytest -q -p no:cacheprovider --durations=30

# The docs site (mkdocs.yml) into site/, strict: a broken link or reference fails it.
docs: venv-python $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict -d site

lint: venv-python $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

# The sources stand in protos/ and are imported as oasis_torchrl/proto/<name>.proto, so the
# generated modules land in the package with the package's import paths.
protos: venv-python $(STAMP)
	$(PY) -m grpc_tools.protoc -Ioasis_torchrl/proto=protos --python_out=. --grpc_python_out=. \
		--pyi_out=. protos/*.proto

# The whole installed set, pinned (the project's own editable installs left out), under the
# header comment of constraints.txt.
lock: venv-python $(STAMP)
	{ sed -n '1,/^[^#]/p' constraints.txt | sed '$$d'; \
		$(PY) -m pip freeze --exclude-editable; } > constraints.tmp
	mv constraints.tmp constraints.txt

# The quick benchmarks (each a few minutes at most; benchmarks/_*.py are their helpers). The
# long ones have a target each: the learning benchmark and the narrow crop's rule train policies
# for hours, Ray across nodes builds network namespaces (root), and the viewer's load time needs
# Chromium (the browser tests' own).
LEARNING_BENCH := benchmarks/learning.py
CROP_RULE_BENCH := benchmarks/front_crop_rule.py
RAY_NODES_BENCH := benchmarks/ray_nodes.py
VIEWER_BENCH := benchmarks/viewer_load.py
LONG_BENCHES := $(LEARNING_BENCH) $(CROP_RULE_BENCH) $(RAY_NODES_BENCH) $(VIEWER_BENCH)
bench: venv-python $(STAMP)
	set -e; for script in $(filter-out $(LONG_BENCHES),$(wildcard benchmarks/[!_]*.py)); do \
		$(PY) $$script; done

bench-learning: venv-python $(STAMP)
	$(PY) $(LEARNING_BENCH)

bench-crop-rule: venv-python $(STAMP)
	$(PY) $(CROP_RULE_BENCH)

bench-ray-nodes: venv-python $(STAMP)
	$(PY) $(RAY_NODES_BENCH)

bench-viewer: venv-python $(STAMP)
	$(PY) $(VIEWER_BENCH)

# LeRobot's fast video path (torchcodec) needs FFmpeg's shared libraries, which no wheel ships under
# the names torchcodec loads; Debian's and Ubuntu's packages do (root needed: `sudo make ffmpeg-libs`).
# Without them LeRobot decodes with PyAV.
ffmpeg-libs:
	apt-get update -q
	apt-get install -y -q --no-install-recommends ffmpeg

clean-venv:
	rm -rf $(VENV)
