# depthbench: two commands on a fresh machine.
#   make demo   - virtual environment, install everything, run the demo on a simulated rig
#   make test   - install, then run the test suite
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
DEMO_OUT ?= demo_out
PYTEST_ARGS ?=

.PHONY: all demo test install sysdeps bench clean

all: test

# System library needed by pyrealsense2 (libusb-1.0) and Chromium for the report test.
# Installed with apt-get when we are root on Debian; otherwise we say exactly what is missing.
sysdeps:
	@./scripts/sysdeps.sh

$(STAMP): pyproject.toml scripts/sysdeps.sh
	@./scripts/sysdeps.sh
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	# torch first, pinned, so nothing later pulls a CUDA build
	$(BIN)/python -m pip install -q "torch==2.13.0"
	$(BIN)/python -m pip install -q -e ".[test]"
	@touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/depthbench demo --out $(DEMO_OUT) --force

test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile $(PYTEST_ARGS)

bench: $(STAMP)
	@for f in perf/*.py; do echo "== $$f"; $(BIN)/python $$f || exit 1; done

clean:
	rm -rf $(VENV) $(DEMO_OUT) .pytest_cache
