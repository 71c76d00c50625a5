#!/bin/sh
# Static analysis of firmware/ (excluding the cantools-generated firmware/can/generated/):
#   cppcheck --enable=warning,style,performance,portability (float and double builds)
#   clang-tidy bugprone-*, cert-*, clang-analyzer-* (float and double builds of the library)
# Findings listed in tests/static/suppressions.txt (each with its justification) are accepted;
# anything else -- or a suppression that matches nothing any more -- fails (exit 1).
# Needs: cppcheck, clang-tidy, clang (for the compile database), cmake.  Exit 2 if missing.
# Environment: NTE_STATIC_BUILD (default build/static), NTE_STATIC_JOBS (default 2).
set -u
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
exec python3 "$HERE/static_check.py" --root "$ROOT" \
    --build "${NTE_STATIC_BUILD:-$ROOT/build/static}" --jobs "${NTE_STATIC_JOBS:-2}" \
    --suppressions "$HERE/suppressions.txt" "$@"
