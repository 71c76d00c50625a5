#!/usr/bin/env bash
# demo.sh: the whole CAN chain (make demo runs it).
#   host_bench/demo.sh [OUT_DIR]
# On the host: simulates a paper insertion (nte-ref simulate).  In a kernel with vcan0
# (host_bench/with-vcan boots one unless this host has vcan; only what needs the bus runs there):
# starts nte-node on vcan0, replays the scenario with the bench (depth 1 kHz, force 200 Hz;
# canplayer drives the bus at full rate), records what the node publishes, stops the node by its
# PID.  On the host again: compares the node's own record of what it sent with the reference fed
# the same frames
# (nte-bench check), prints the agreement and the final parameters and writes the figures
# (OUT_DIR/force.png, OUT_DIR/params.png).
# Environment: NTE_NODE (default build/host/bin/nte-node, else build/node/bin/nte-node),
#              NTE_DEMO_SPEED (default 1), NTE_DEMO_PLAYER (canplayer | python, default canplayer);
#              with-vcan's own (WITH_VCAN_MODE, ...).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/.." && pwd)"
py="$repo/.venv/bin/python"; [[ -x "$py" ]] || py=python3

if [[ "${1:-}" == --on-bus ]]; then
    # ---- inside the kernel: the node and the bench's sender/recorder, nothing else
    out="$2"; node="$3"
    rm -f "$out/node.ready"
    "$node" --iface vcan0 --model 2 --preset paper-10mms --ready "$out/node.ready" \
        --stats "$out/node-stats.json" --record "$out/node-sent.log" 2>"$out/node.err" &
    node_pid=$!
    stop_node() {
        if kill -0 "$node_pid" 2>/dev/null; then
            kill -TERM "$node_pid"
            wait "$node_pid" || true
        fi
    }
    trap stop_node EXIT
    for _ in $(seq 1 600); do [[ -f "$out/node.ready" ]] && break; sleep 0.05; done
    [[ -f "$out/node.ready" ]] || { cat "$out/node.err" >&2; echo "demo.sh: node did not start" >&2; exit 1; }
    "$py" -m host_bench.cli replay "$out/insertion.csv" --channel vcan0 \
        --player "${NTE_DEMO_PLAYER:-canplayer}" --speed "${NTE_DEMO_SPEED:-1}" \
        --model 2 --preset paper-10mms --no-check --no-progress --out "$out"
    stop_node
    trap - EXIT
    exit 0
fi

out="${1:-$repo/out/demo-can}"
mkdir -p "$out"
out="$(cd "$out" && pwd)"
node="${NTE_NODE:-}"
if [[ -z "$node" ]]; then
    for c in "$repo/build/host/bin/nte-node" "$repo/build/node/bin/nte-node"; do
        [[ -x "$c" ]] && { node="$c"; break; }
    done
fi
[[ -x "$node" ]] || { echo "demo.sh: nte-node not built (cmake --build build/host)" >&2; exit 2; }

"$py" -m reference_py simulate --preset paper-10mms --depth 50 --dwell 1 --seed 1 \
    --out "$out/insertion.csv" >/dev/null
"$here/with-vcan" "$here/demo.sh" --on-bus "$out" "$node"
status=0
# the node's own record of what it sent: complete even when the bench's recorder, on a loaded
# machine, misses frames (the bench's count beside it shows how many reached it)
"$py" -m host_bench.cli check "$out" --node-log "$out/node-sent.log" --model 2 \
    --preset paper-10mms || status=$?
echo "node counters: $(cat "$out/node-stats.json")"
echo "figures: $out/force.png $out/params.png"
exit $status
