# Entry points (run as root on Debian 12 from the repository root):
#   make demo   - simulate a paper insertion, run the estimator on it, print and plot the result
#   make test   - every test: C unit tests (ctest) and the Python suite (pytest)
#   make        - build the firmware for the host (build/host)
#   make board  - the Cortex-M4F board images (build/m4)
# Each target installs what it needs (Debian packages, the .venv) and is quick when it is there.

SHELL := /bin/bash
PYTHON_SYS ?= /usr/bin/python3
VENV := .venv
PY := $(VENV)/bin/python
BUILD := build/host
DEMO_DIR := out/demo

# Debian packages the build and the tests need
APT_PACKAGES := python3 python3-venv python3-dev gcc make cmake libcmocka-dev libcjson-dev cppcheck \
                user-mode-linux kmod can-utils iproute2 \
                qemu-system-x86 linux-image-amd64 busybox-static cpio \
                gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm \
                clang clang-tidy clang-format libclang-rt-14-dev

.PHONY: all build board board-figures products clang demo test deps venv clean

all: build

deps:
	@missing=""; for p in $(APT_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  export DEBIAN_FRONTEND=noninteractive; \
	  apt-get update -qq && apt-get install -y -qq --no-install-recommends $$missing; \
	fi

$(VENV)/.installed: pyproject.toml | deps
	test -x $(PY) || $(PYTHON_SYS) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $@

venv: $(VENV)/.installed

build: deps
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release > /dev/null
	cmake --build $(BUILD) -j2

# the Cortex-M4F board image (build/m4/bin/nte-board.elf, .bin, .hex) and the self-test (the
# self-test's host twin, nte-selftest-host, is part of build/host)
# a build tree configured before the images were linked with -flto keeps its cached flags
board: deps
	if [ -f build/m4/CMakeCache.txt ] && ! grep -q -- -flto build/m4/CMakeCache.txt; then \
	  rm -rf build/m4; fi
	cmake -S . -B build/m4 -DCMAKE_TOOLCHAIN_FILE=cmake/arm-none-eabi.cmake > /dev/null
	cmake --build build/m4 -j2

# CI: what users need builds without the tests (and without cmocka), from a fresh tree: the
# host programs and the Linux node, and the board image
products: deps
	rm -rf build/products
	cmake -S . -B build/products/host -DCMAKE_BUILD_TYPE=Release -DNTE_BUILD_TESTS=OFF > /dev/null
	! grep -q '^CMOCKA_' build/products/host/CMakeCache.txt
	cmake --build build/products/host -j2 --target nte-node nte-run
	cmake -S . -B build/products/m4 -DCMAKE_TOOLCHAIN_FILE=cmake/arm-none-eabi.cmake \
	  -DNTE_BUILD_TESTS=OFF > /dev/null
	cmake --build build/products/m4 -j2 --target nte-board

# CI: the same tree with clang (same strict flags, -Werror), and its C tests
clang: deps
	cmake -S . -B build/clang -DCMAKE_C_COMPILER=clang -DCMAKE_BUILD_TYPE=Release > /dev/null
	cmake --build build/clang -j2
	cd build/clang && ctest --output-on-failure -j2

board-figures: venv board
	$(PY) firmware/port/mps2-an386/figures.py
	$(PY) firmware/port/mps2-an386/cycles.py --functions 6

# the whole chain: the C node on a real vcan0 (host_bench/with-vcan boots a kernel when the host has no CAN),
# fed by the host bench with a paper insertion, compared bit for bit with the reference
demo: venv build
	mkdir -p $(DEMO_DIR)
	host_bench/demo.sh $(CURDIR)/$(DEMO_DIR)/can
	$(VENV)/bin/nte-ref estimate $(DEMO_DIR)/can/insertion.csv --model 2 --estimator robust \
	  --preset paper-10mms --init-seed 7 --init-factor 5 --out $(DEMO_DIR)/robust.csv \
	  --plot $(DEMO_DIR)/robust.png

test: venv build board products clang
	cd $(BUILD) && ctest --output-on-failure
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -n 2 --dist loadfile --no-loadscope-reorder tests

clean:
	rm -rf build out

# the README's figures (reference_py/figures/*.png) from the commands in
# reference_py/figures/make_figures.sh (about a minute)
.PHONY: figures
figures: venv
	reference_py/figures/make_figures.sh
