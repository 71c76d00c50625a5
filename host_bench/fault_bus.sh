#!/usr/bin/env bash
# fault_bus.sh NODE DIR [keep]: the bus half of the fault table over vcan0 (python -m
# host_bench.faults --bus vcan), run where vcan0 exists -- inside the kernel host_bench/with-vcan
# provides.  Only what needs AF_CAN runs here (nte-node and can-utils' canplayer): the faulted
# input logs were written on the host beforehand and the scoring runs on the host afterwards
# (host_bench/fault_bus.py), so a kernel under QEMU's TCG costs seconds, not minutes.
#
# DIR/plan holds one node run per line, "TAG END", in order; each run:
#   1. starts a fresh nte-node on vcan0 (Model II, preset paper-10mms, its kernel filters on) in
#      its own process group, and waits for its ready file (its socket is bound);
#   2. plays DIR/TAG.in.log with canplayer (the log's own pacing: the host scaled its times);
#   3. waits until the node has read the whole log: the log ends with a Command (AdaptCmd
#      resume, which changes nothing), and the node's counters -- asked for with SIGUSR1 --
#      show it applied;
#   4. END "stop": SIGTERM to the node's process group (SIGKILL after 10 s).  END "kill":
#      SIGKILL to the group at once, as a crash or a power cut (its logs' unwritten buffers are
#      lost with it; its counters were read in step 3).
# The node writes what it received and sent (--received, --record) and its counters (--stats)
# to a directory in /dev/shm (a file system in memory: in a kernel under TCG every write to the
# shared host file system costs milliseconds); after the run DIR/TAG.stats.json, .sent.log,
# .node.err, .exit (its exit status) and .recv ("COUNT MD5": the frames it received, and the
# MD5 of their "ID#DATA" fields one a line, in order) are written; .recv.log too with "keep".
# DIR/TAG.done ("RUN START PLAY READ STOP COPY": seconds the run took, and its phases: the
# node's start, canplayer, the node's reading after it, its stop, the copy of its logs) or
# DIR/TAG.failed (why); DIR/pids lists the nodes' process group ids, one per run started.
# Exit status 0 when every run is done, 1 otherwise (the runs after a failed one never start).
# Every process started here is stopped by its own id: the nodes by their process groups, also
# when a run fails or this script is stopped (SIGTERM, SIGINT: the groups get SIGKILL at once).
# Waiting uses bash builtins only (a timed read on a FIFO, no `sleep`): under TCG every process
# started costs some 0.15 s of the guest.
set -uo pipefail
NODE="$1"; DIR="$2"; KEEP="${3:-}"
# shellcheck source=host_bench/one_cpu.sh
source "$(dirname "${BASH_SOURCE[0]}")/one_cpu.sh"
READY_S=60        # a kernel under TCG on a loaded host starts a process slowly
DRAIN_S=600       # and may read a flooded log slowly: a limit, not a measure

groups=()         # process groups of the nodes started and not yet reaped
shm="$(mktemp -d /dev/shm/nte-faults.XXXXXX 2>/dev/null || mktemp -d)"
mkfifo "$shm/nap" && exec {nap_fd}<>"$shm/nap"
nap() { read -r -t "$1" -u "$nap_fd" _ || true; }       # sleep $1 s, no process

kill_all() {      # SIGKILL every node group still there (on failure or when stopped)
    local g
    for g in "${groups[@]}"; do kill -KILL -- "-$g" 2>/dev/null; done
    groups=()
}
cleanup() { kill_all; rm -rf "$shm"; }
trap cleanup EXIT
trap 'exit 143' TERM
trap 'exit 130' INT

secs() { printf -v "$1" '%d.%02d' $(( $2 / 1000000 )) $(( $2 % 1000000 / 10000 )); }  # VAR us

# stop_group PGID SIGNAL: SIGNAL to the group (TERM: SIGKILL after 10 s if it is still there),
# reap the node; its exit status in $stopped, the group no longer ours
stopped=""
stop_group() {
    local g="$1" i keep=()
    kill "-$2" -- "-$g" 2>/dev/null
    for (( i = 0; i < 200; i++ )); do kill -0 -- "-$g" 2>/dev/null || break; nap 0.05; done
    kill -KILL -- "-$g" 2>/dev/null
    wait "$g" 2>/dev/null
    stopped=$?
    for i in "${groups[@]}"; do [[ "$i" != "$g" ]] && keep+=("$i"); done
    groups=("${keep[@]}")
}

# stats_show PID FILE PATTERN: ask the node for its counters (SIGUSR1) until PATTERN is in FILE
stats_show() {
    local pid="$1" file="$2" pattern="$3" i text
    for (( i = 0; i < DRAIN_S * 20; i++ )); do
        kill -0 "$pid" 2>/dev/null || { echo "the node ($pid) exited before reading its log" >&2; return 1; }
        kill -USR1 "$pid" 2>/dev/null
        nap 0.05
        text=""
        [[ -f "$file" ]] && IFS= read -r -d '' text <"$file"
        [[ "$text" == *"$pattern"* ]] && return 0
    done
    echo "the node did not read its whole log within ${DRAIN_S} s: $text" >&2
    return 1
}

run() {           # TAG END
    local tag="$1" end="$2" pid i text t0 t_ready t_played t_read t_stopped
    local base="$shm/$tag"
    t0=${EPOCHREALTIME/[.,]/}
    # setsid: the node leads its own process group (its pid is the group's id)
    setsid "$NODE" --iface vcan0 --model 2 --preset paper-10mms --ready "$base.ready" \
        --stats "$base.stats.json" --record "$base.sent.log" --received "$base.recv.log" \
        </dev/null >/dev/null 2>"$base.node.err" &
    pid=$!; groups+=("$pid")
    echo "$pid" >>"$DIR/pids"          # for whoever checks that none is left
    for (( i = 0; i < READY_S * 20; i++ )); do
        [[ -f "$base.ready" ]] && break
        kill -0 "$pid" 2>/dev/null || break
        nap 0.05
    done
    if [[ ! -f "$base.ready" ]]; then
        echo "nte-node did not start: $(<"$base.node.err")" >&2; return 1
    fi
    t_ready=${EPOCHREALTIME/[.,]/}
    one_cpu canplayer -I "$DIR/$tag.in.log" ||
        { echo "canplayer failed on $tag.in.log" >&2; return 1; }
    t_played=${EPOCHREALTIME/[.,]/}
    stats_show "$pid" "$base.stats.json" '"commands_applied": 1,' || return 1
    t_read=${EPOCHREALTIME/[.,]/}
    # killed: its counters stay those it had read the whole log with (no signal asked for
    # more, and a rewrite is atomic); stopped: the final ones, written at its exit
    local sig=TERM
    [[ "$end" == kill ]] && sig=KILL
    stop_group "$pid" "$sig"
    echo "$stopped" >"$base.exit"
    t_stopped=${EPOCHREALTIME/[.,]/}
    # what it received, as a count and a digest of its "ID#DATA" fields in order (the whole log
    # would cross to the host's file system for nothing: the host knows what was played)
    awk -v n="$base.n" '{ print $3 } END { print NR >n }' "$base.recv.log" | md5sum >"$base.md5"
    IFS= read -r i <"$base.n"
    read -r text _ <"$base.md5"
    echo "$i $text" >"$base.recv"
    local files=("$base.stats.json" "$base.sent.log" "$base.node.err" "$base.exit" "$base.recv")
    [[ -n "$KEEP" ]] && files+=("$base.recv.log")
    cp "${files[@]}" "$DIR/"
    local b=${EPOCHREALTIME/[.,]/}
    local s1 s2 s3 s4 s5 s6        # printf -v: no subshell
    secs s1 $(( b - t0 )); secs s2 $(( t_ready - t0 )); secs s3 $(( t_played - t_ready ))
    secs s4 $(( t_read - t_played )); secs s5 $(( t_stopped - t_read )); secs s6 $(( b - t_stopped ))
    echo "$s1 $s2 $s3 $s4 $s5 $s6" >"$DIR/$tag.done"
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
