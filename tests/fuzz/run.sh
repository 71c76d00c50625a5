#!/bin/sh
# Build the libFuzzer harnesses (clang) and run each for SECONDS (default 20).
#   tests/fuzz/run.sh [SECONDS] [HARNESS...]     HARNESS in: node config_f32 config_f64 csv
# SECONDS 0 only builds.
# Prints per harness the executions and crashes, then the totals; exit status 1 if any harness
# crashed (a property abort(), a sanitizer finding, a timeout or out-of-memory), 2 on a build
# error.  Crashing inputs are kept in build/fuzz/artifacts/<harness>/; the corpus grown by a run
# stays in build/fuzz/corpus/<harness>/ (the committed seeds are in tests/fuzz/corpus/).
# Environment: CC (default clang), NTE_FUZZ_BUILD (default build/fuzz), NTE_FUZZ_JOBS;
# NTE_FUZZ_RUNS=N runs exactly N inputs per harness from seed 1 and an empty working corpus
# instead of SECONDS: the same inputs on every machine and load (what the test suite uses).
set -u
SECONDS_EACH=${1:-20}
[ $# -gt 0 ] && shift
HARNESSES=${*:-"node config_f32 config_f64 csv"}
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
BUILD=${NTE_FUZZ_BUILD:-$ROOT/build/fuzz}
CC=${CC:-clang}
export CC

if ! command -v "$CC" >/dev/null 2>&1; then
    echo "run.sh: $CC not found (apt-get install -y clang libclang-rt-14-dev)" >&2
    exit 2
fi
cmake -S "$HERE" -B "$BUILD" -DCMAKE_BUILD_TYPE=RelWithDebInfo >"$BUILD.configure.log" 2>&1 \
    || { cat "$BUILD.configure.log" >&2; exit 2; }
cmake --build "$BUILD" -j"${NTE_FUZZ_JOBS:-2}" >"$BUILD.build.log" 2>&1 \
    || { tail -40 "$BUILD.build.log" >&2; exit 2; }

if [ "$SECONDS_EACH" -le 0 ]; then
    echo "fuzz: built in $BUILD/bin (SECONDS=0: nothing run)"
    exit 0
fi

ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1}
UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
export ASAN_OPTIONS UBSAN_OPTIONS

total_exec=0
total_crash=0
for h in $HARNESSES; do
    seeds=$HERE/corpus/${h%_f32}
    seeds=${seeds%_f64}
    corpus=$BUILD/corpus/$h
    art=$BUILD/artifacts/$h
    rm -rf "$art"
    if [ -n "${NTE_FUZZ_RUNS:-}" ]; then
        corpus=$BUILD/corpus-fixed/$h      # deterministic: start from the committed seeds only
        rm -rf "$corpus"
        budget="-runs=$NTE_FUZZ_RUNS -seed=1"
    else
        budget="-max_total_time=$SECONDS_EACH"
    fi
    mkdir -p "$corpus" "$art"
    log=$BUILD/$h.log
    # -timeout: one input taking longer is a finding (a hang); -rss_limit_mb: memory blow-up.
    # shellcheck disable=SC2086  # $budget is two options
    "$BUILD/bin/fuzz_$h" $budget -timeout=10 -rss_limit_mb=2048 \
        -print_final_stats=1 -artifact_prefix="$art/" "$corpus" "$seeds" >"$log" 2>&1
    rc=$?
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    execs=${execs:-0}
    crashes=$(find "$art" -type f \( -name 'crash-*' -o -name 'timeout-*' -o -name 'oom-*' \
        -o -name 'leak-*' \) | wc -l)
    if [ "$rc" -ne 0 ] && [ "$crashes" -eq 0 ]; then
        crashes=1 # died without an artifact (e.g. a sanitizer report during start-up)
    fi
    findings=$(grep -c -E '^(==[0-9]+==ERROR|SUMMARY: (Address|UndefinedBehavior)Sanitizer)|runtime error:' "$log")
    echo "fuzz $h: executions=$execs crashes=$crashes sanitizer_reports=$findings seconds=$SECONDS_EACH"
    if [ "$crashes" -ne 0 ]; then
        grep -E 'property violated|runtime error|ERROR: (AddressSanitizer|libFuzzer)|Test unit written' "$log" | head -8 | sed 's/^/    /'
    fi
    total_exec=$((total_exec + execs))
    total_crash=$((total_crash + crashes))
done
echo "fuzz total: executions=$total_exec crashes=$total_crash"
[ "$total_crash" -eq 0 ]
