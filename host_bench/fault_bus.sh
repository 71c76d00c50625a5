#!/usr/bin/env bash
# fault_bus.sh NODE DIR [keep]: the bus half of the fault table over vcan0 (python -m host_bench.faults
# --bus vcan), run where vcan0 exists -- inside the kernel host_bench/with-vcan provides.  Only
# what needs AF_CAN runs here (nte-node and can-utils' canplayer): the faulted input logs were
# written on the host beforehand and the scoring runs on the host afterwards
# (host_bench/fault_bus.py), so a kernel under QEMU's TCG costs seconds, not minutes.
#
# DIR/plan holds one node run per line, "TAG END", in order; each run:
#   1. starts a fresh nte-node on vcan0 (Model II, preset paper-10mms, its kernel filters on) in
#      its own process group, and waits for its ready file (its socket is bound);
#   2. plays DIR/TAG.in.log with canplayer (the log's own pacing: the host scaled its times);
#   3. waits until the node has read the whole log: the log ends with a Command (AdaptCmd
#      resume, which changes nothing), and the node's counters -- asked for with SIGUSR1 --
#      show it applied;
#   4. END "stop": SIGTERM to the node's process group (SIGKILL after 10 s); its exit status in
#      DIR/TAG.exit.  END "kill": SIGKILL to the group at once, as a crash or a power cut (its
#      logs' unwritten buffers are lost with it; its counters were read in step 3).
# The node writes what it received and sent (--received, --record) and its counters (--stats)
# to a directory in /dev/shm (a file system in memory: in a kernel under TCG every write to the
# shared host file system costs milliseconds); after the run DIR/TAG.stats.json, .sent.log,
# .node.err, .exit (its exit status) and .recv ("COUNT MD5": the frames it received, and the
# MD5 of their "ID#DATA" fields one a line, in order) are written; .recv.log too with "keep".
# DIR/pids lists the node's process group ids, one per run started.
# Every process started here is stopped by its own id: the nodes by their process groups, also
# when a run fails or this script is stopped (SIGTERM, SIGINT: the groups get SIGKILL at once).
# DIR/TAG.done (seconds: the run, the node's start, the play, its reading after it, its stop, the
# copy of its logs) or DIR/TAG.failed (why) per run; exit status 0 when every
# run is done, 1 otherwise (the runs after a failed one are not started).
set -uo pipefail
NODE="$1"; DIR="$2"; KEEP="${3:-}"
READY_S=60        # a kernel under TCG on a loaded host starts a process slowly
DRAIN_S=600       # and may read a flooded log slowly: a limit, not a measure

groups=()         # process groups of the nodes started and not yet reaped
shm="$(mktemp -d /dev/shm/nte-faults.XXXXXX 2>/dev/null || mktemp -d)"

gone() { ! kill -0 -- "-$1" 2>/dev/null; }
kill_all() {      # SIGKILL every node group still there (on failure or when stopped)
    local g
    for g in "${groups[@]}"; do kill -KILL -- "-$g" 2>/dev/null; done
    groups=()
}
cleanup() { kill_all; rm -rf "$shm"; }
trap cleanup EXIT
trap 'exit 143' TERM
trap 'exit 130' INT

forget() {        # PGID: no longer ours to stop
    local g keep=()
    for g in "${groups[@]}"; do [[ "$g" != "$1" ]] && keep+=("$g"); done
    groups=("${keep[@]}")
}

# stop_group PGID SIGNAL: SIGNAL to the group (TERM: SIGKILL after 10 s if it is still there),
# reap the node; its exit status in $stopped
stopped=""
stop_group() {
    local g="$1" _
    kill "-$2" -- "-$g" 2>/dev/null
    for _ in $(seq 1 200); do gone "$g" && break; sleep 0.05; done
    kill -KILL -- "-$g" 2>/dev/null
    wait "$g" 2>/dev/null
    stopped=$?
    forget "$g"
}

# stats_show PID FILE PATTERN: ask the node for its counters (SIGUSR1) until PATTERN is in FILE
stats_show() {
    local pid="$1" file="$2" pattern="$3" i
    for (( i = 0; i < DRAIN_S * 10; i++ )); do
        kill -0 "$pid" 2>/dev/null || { echo "the node ($pid) exited before reading its log" >&2; return 1; }
        kill -USR1 "$pid" 2>/dev/null
        sleep 0.1
        grep -q -- "$pattern" "$file" 2>/dev/null && return 0
    done
    echo "the node did not read its whole log within ${DRAIN_S} s: $(cat "$file" 2>/dev/null)" >&2
    return 1
}

run() {           # TAG END
    local tag="$1" end="$2" t0=$EPOCHREALTIME pid _
    local base="$shm/$tag"
    rm -f "$DIR/$tag".{done,failed,exit,stats.json,sent.log,recv.log,node.err}
    # setsid: the node leads its own process group (its pid is the group's id)
    setsid "$NODE" --iface vcan0 --model 2 --preset paper-10mms --ready "$base.ready" \
        --stats "$base.stats.json" --record "$base.sent.log" --received "$base.recv.log" \
        </dev/null >/dev/null 2>"$base.node.err" &
    pid=$!; groups+=("$pid")
    echo "$pid" >>"$DIR/pids"          # for whoever checks that none is left
    for _ in $(seq 1 $(( READY_S * 20 ))); do
        [[ -f "$base.ready" ]] && break
        kill -0 "$pid" 2>/dev/null || break
        sleep 0.05
    done
    if [[ ! -f "$base.ready" ]]; then
        echo "nte-node did not start: $(cat "$base.node.err")" >&2; return 1
    fi
    local t_ready=$EPOCHREALTIME
    canplayer -I "$DIR/$tag.in.log" || { echo "canplayer failed on $tag.in.log" >&2; return 1; }
    local t_played=$EPOCHREALTIME
    stats_show "$pid" "$base.stats.json" '"commands_applied": 1,' || return 1
    local t_read=$EPOCHREALTIME
    if [[ "$end" == kill ]]; then
        cp "$base.stats.json" "$DIR/$tag.stats.json"    # the counters it had read all with
        stop_group "$pid" KILL
    else
        stop_group "$pid" TERM
        cp "$base.stats.json" "$DIR/$tag.stats.json"    # the final counters, written at exit
    fi
    echo "$stopped" >"$DIR/$tag.exit"
    local t_stopped=$EPOCHREALTIME
    # what it received, as a count and a digest of its "ID#DATA" fields in order (the whole log
    # would cross to the host file system for nothing: the host knows what was played)
    echo "$(wc -l <"$base.recv.log") $(cut -d' ' -f3 "$base.recv.log" | md5sum | cut -c1-32)" \
        >"$DIR/$tag.recv"
    local f
    for f in sent.log node.err ${KEEP:+recv.log}; do
        [[ -f "$base.$f" ]] && cp "$base.$f" "$DIR/$tag.$f"
    done
    rm -f "$base".*
    # seconds: the whole run, the node's start, canplayer, the node's reading after it, its
    # stop, the copy of its logs
    awk -v a="$t0" -v r="$t_ready" -v p="$t_played" -v d="$t_read" -v s="$t_stopped" \
        -v b="$EPOCHREALTIME" 'BEGIN { printf "%.2f %.2f %.2f %.2f %.2f %.2f\n", b - a, r - a,
        p - r, d - p, s - d, b - s }' >"$DIR/$tag.done"
}

rm -f "$DIR/pids"
while read -r tag end; do
    [[ -z "$tag" ]] && continue
    if ! run "$tag" "$end" 2>"$shm/why"; then
        { echo "run $tag failed:"; cat "$shm/why"; } >"$DIR/$tag.failed"
        kill_all
        exit 1
    fi
done <"$DIR/plan"
exit 0
