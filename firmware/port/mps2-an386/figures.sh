#!/bin/sh
# Prints the board image's figures (see figures.py); builds the cross tree first.
#   firmware/port/mps2-an386/figures.sh
set -eu
cd "$(dirname "$0")/../../.."
cmake -S . -B build/m4 -DCMAKE_TOOLCHAIN_FILE=cmake/arm-none-eabi.cmake >/dev/null
cmake --build build/m4 -j2 >/dev/null
python3 firmware/port/mps2-an386/figures.py --build build/m4
exec python3 firmware/port/mps2-an386/cycles.py --build build/m4
