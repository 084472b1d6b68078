# Two commands on a fresh machine: `make demo` (the main job, on the embedded local server) and
# `make test` (the whole suite). Both create or reuse .venv and install the pinned dependency set.

PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
EXTRAS := dev,lerobot,rerun,depth,ray
DEMO_OUT ?= outputs/demo

.PHONY: demo test lint protos lock bench clean-venv

$(STAMP): pyproject.toml policies/pyproject.toml constraints.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade "pip>=24"
	$(PY) -m pip install --quiet -c constraints.txt -e ".[$(EXTRAS)]"
	$(PY) -m pip install --quiet -c constraints.txt --no-deps -e policies/
	touch $(STAMP)

demo: $(STAMP)
	$(PY) -m oasis_torchrl demo output_dir=$(DEMO_OUT)

test: $(STAMP)
	$(PY) -m pytest -q -p no:cacheprovider

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

protos: $(STAMP)
	$(PY) -m grpc_tools.protoc -Iprotos --python_out=. --grpc_python_out=. --pyi_out=. \
		$$(cd protos && find . -name '*.proto' | sed 's|^\./|protos/|')

lock: $(STAMP)
	{ sed -n '1,2p' constraints.txt; $(PY) -m pip freeze --exclude-editable; } > constraints.tmp
	mv constraints.tmp constraints.txt

bench: $(STAMP)
	for script in benchmarks/*.py; do $(PY) $$script; done

clean-venv:
	rm -rf $(VENV)
