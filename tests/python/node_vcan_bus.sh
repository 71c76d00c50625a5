#!/usr/bin/env bash
# node_vcan_bus.sh NODE OUT CASE...: the bus half of test_node_vcan.py, run inside the session's
# kernel by host_bench/with-vcan.  Only what needs AF_CAN runs here -- nte-node, canplayer,
# candump, cangen, nte-bench settings -- so a kernel under QEMU's TCG costs seconds; the input logs were written on
# the host beforehand (node_vcan_driver.py prepare) and the analysis runs on the host afterwards
# (node_vcan_driver.py analyse).  Every process is started here and stopped by its PID, also
# when a case fails.  Each case leaves OUT/<case>.done (or OUT/<case>.failed with the reason).
# Environment: NTE_ENOBUFS_SHIM = the LD_PRELOAD library of the enobufs case.  The settings
# case runs the bench's sender (.venv/bin/nte-bench settings) here too: it sends on vcan0.
set -uo pipefail
NODE="$1"; OUT="$2"; shift 2
BENCH="$(cd "$(dirname "$0")/../.." && pwd)/.venv/bin/nte-bench"
# shellcheck source=host_bench/one_cpu.sh
source "$(dirname "$0")/../../host_bench/one_cpu.sh"
FRAME_DEPTH=$(cat "$OUT/ids/depth")

pids=()
started() { pids+=("$1"); }
stop() {  # PID -> its exit status on stdout
    local pid="$1" _
    if kill -0 "$pid" 2>/dev/null; then
        kill -TERM "$pid" 2>/dev/null
        for _ in $(seq 1 200); do kill -0 "$pid" 2>/dev/null || break; sleep 0.05; done
        kill -KILL "$pid" 2>/dev/null
    fi
    wait "$pid" 2>/dev/null
    echo $?
}
stop_all() {
    local i
    for (( i = ${#pids[@]} - 1; i >= 0; i-- )); do stop "${pids[i]}" >/dev/null; done
    pids=()
}
trap stop_all EXIT

# drained PID LIMIT_S: wait for a `candump -n COUNT` to exit by itself once it has taken all
# COUNT frames (under TCG it lags the bus by seconds, and stopping it half a second after the
# player left the frames still queued in its socket unwritten), at most LIMIT_S; then stop it.
drained() {
    local pid="$1" limit="$2" _
    for _ in $(seq 1 $(( limit * 20 ))); do kill -0 "$pid" 2>/dev/null || break; sleep 0.05; done
    stop "$pid"
}

# rx_filters: how many receive filters the kernel holds on vcan0 (/proc/net/can/rcvlist_fil)
rx_filters() {
    local n; n=$(grep -c '^ *vcan0 ' /proc/net/can/rcvlist_fil 2>/dev/null)
    echo "${n:-0}"
}
# listening BEFORE PID: wait until a receive filter more than BEFORE is on vcan0, i.e. the
# candump PID has bound its socket -- no sleep guesses it (under TCG on a loaded host a process
# takes seconds to start); fails after 60 s or when PID is gone
listening() {
    local before="$1" pid="$2" _
    for _ in $(seq 1 1200); do
        (( $(rx_filters) > before )) && return 0
        kill -0 "$pid" 2>/dev/null || break
        sleep 0.05
    done
    echo "candump ($pid) never bound its socket on vcan0" >&2
    return 1
}

# start_node TAG [ARGS...]: the node on vcan0 with the paper preset; $node_pid; fails if it does
# not say it is ready within 60 s (a kernel under TCG starts processes slowly)
start_node() {
    local tag="$1"; shift
    rm -f "$OUT/$tag.ready"
    "$NODE" --iface vcan0 --model 2 --preset paper-10mms --ready "$OUT/$tag.ready" \
        --stats "$OUT/$tag.stats.json" "$@" 2>"$OUT/$tag.node.err" &
    node_pid=$!; started "$node_pid"
    local _
    for _ in $(seq 1 1200); do
        [[ -f "$OUT/$tag.ready" ]] && return 0
        kill -0 "$node_pid" 2>/dev/null || break
        sleep 0.05
    done
    echo "node did not start: $(cat "$OUT/$tag.node.err")" >&2
    return 1
}

play() { one_cpu canplayer -I "$1"; }

case_full_rate() {
    # the outputs from the node's own record of what it sent (a candump of the outputs in a
    # loaded kernel dropped frames); the input ids recorded with candump -l for the session replay
    start_node full --record "$OUT/full.sent.log" || return 1
    rm -rf "$OUT/session"; mkdir -p "$OUT/session"
    local count; count=$(grep -c . "$OUT/full_in.log")   # every frame of it is an input id
    local before; before=$(rx_filters)
    (cd "$OUT/session" && exec candump -l -n "$count" -r 16000000 "vcan0,$FRAME_DEPTH:7FC" \
        2>/dev/null) &
    local rec=$!; started "$rec"
    listening "$before" "$rec" || return 1
    play "$OUT/full_in.log" || return 1
    drained "$rec" 300 >/dev/null
    stop "$node_pid" >"$OUT/full.exit"
    local session; session="$(ls "$OUT"/session/candump-*.log | head -n 1)"
    start_node again --record "$OUT/again.sent.log" || return 1
    play "$session" || return 1
    sleep 0.5
    stop "$node_pid" >/dev/null
}

case_bad_traffic() {
    # the node's own logs, not a candump: under TCG a candump writing to the shared filesystem
    # dropped frames (once the Command itself), and the comparison must be exact in every run
    start_node bad --no-kernel-filter --record "$OUT/bad.sent.log" \
        --received "$OUT/bad.recv.log" || return 1
    play "$OUT/bad_in.log" || return 1
    sleep 0.5
    stop "$node_pid" >/dev/null
}

case_cangen() {
    start_node gen --record "$OUT/gen.sent.log" --received "$OUT/gen.recv.log" || return 1
    local t0=$EPOCHREALTIME
    cangen vcan0 -g 2 -I r -L r -D r >/dev/null 2>&1 &
    local gen=$!; started "$gen"
    play "$OUT/gen_in.log" || return 1
    # 60 s of random traffic in all
    local left; left=$(awk -v a="$t0" -v b="$EPOCHREALTIME" 'BEGIN { d = 60 - (b - a); print (d > 0 ? d : 0) }')
    sleep "$left"
    stop "$gen" >/dev/null
    awk -v a="$t0" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.3f\n", b - a }' >"$OUT/gen.cangen_s"
    sleep 0.5
    stop "$node_pid" >/dev/null
}

case_burst() {
    start_node burst --record "$OUT/burst.sent.log" --received "$OUT/burst.recv.log" || return 1
    play "$OUT/burst_in.log" || return 1
    sleep 0.5
    stop "$node_pid" >/dev/null
}

case_enobufs() {
    # the node's next 200 send() calls fail with ENOBUFS (LD_PRELOAD shim) once OUT/enobufs.flag
    # exists, 3 s into the replay: about 0.8 s of its frames, a count whatever the machine's
    # speed (the replay has some 3 500 sends left then)
    local flag="$OUT/enobufs.flag" sends=200
    rm -f "$flag"
    echo "$sends" >"$OUT/nobuf.sends"
    # what went out is taken from the node's own record of its successful sends (a candump
    # under TCG writing to the shared filesystem dropped frames)
    LD_PRELOAD="$NTE_ENOBUFS_SHIM" NTE_ENOBUFS_FILE="$flag" NTE_ENOBUFS_SENDS="$sends" \
        start_node nobuf --record "$OUT/nobuf.sent.log" || return 1
    one_cpu canplayer -I "$OUT/nobuf_in.log" &
    local p=$!; started "$p"
    sleep 3.0
    echo 1 >"$flag"
    wait "$p" || return 1
    rm -f "$flag"
    sleep 0.5
    if kill -0 "$node_pid" 2>/dev/null; then echo 1; else echo 0; fi >"$OUT/nobuf.alive"
    stop "$node_pid" >/dev/null
}

case_model3() {
    # a Model II node; the Command selecting Model III is in the input log (at 0.5 s)
    start_node model3 --record "$OUT/model3.sent.log" --received "$OUT/model3.recv.log" || return 1
    play "$OUT/model3_in.log" || return 1
    sleep 0.5
    stop "$node_pid" >/dev/null
}

case_predict_only() {
    # the paper scenario's first seconds with ForceSource commands, a SensorFault stretch and
    # a lost force sensor in the input log; the mirror is fed the node's own received log
    start_node po --record "$OUT/po.sent.log" --received "$OUT/po.recv.log" || return 1
    play "$OUT/po_in.log" || return 1
    sleep 0.5
    stop "$node_pid" >/dev/null
}

case_settings() {
    # a Model II node; nte-bench settings sends the export (Setting frames, python-can), then
    # the phantom's first seconds are played; the node's own logs are analysed on the host
    start_node settings --record "$OUT/settings.sent.log" \
        --received "$OUT/settings.recv.log" || return 1
    "$BENCH" settings "$OUT/settings_m3.json" --channel vcan0 --listen 3 \
        >"$OUT/settings.bench.out" 2>&1
    echo $? >"$OUT/settings.bench.exit"
    play "$OUT/settings_in.log" || return 1
    sleep 0.5
    stop "$node_pid" >/dev/null
}

case_no_iface() {
    "$NODE" --iface vcan9 2>"$OUT/noif.err"
    echo $? >"$OUT/noif.exit"
}

status=0
for c in "$@"; do
    rm -f "$OUT/$c.done" "$OUT/$c.failed"
    t=$EPOCHREALTIME
    if "case_$c" 2>"$OUT/$c.stderr"; then
        awk -v a="$t" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.2f\n", b - a }' >"$OUT/$c.done"
    else
        { echo "case $c failed:"; cat "$OUT/$c.stderr"; } >"$OUT/$c.failed"
        status=1
    fi
    stop_all
done
exit $status
