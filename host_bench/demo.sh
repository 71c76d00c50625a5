#!/usr/bin/env bash
# demo.sh: the whole CAN chain.  Run it inside host_bench/with-vcan (make demo does):
#   host_bench/with-vcan host_bench/demo.sh [OUT_DIR]
# Simulates a paper insertion (nte-ref simulate), starts nte-node on vcan0, replays the
# scenario with the bench (depth 1 kHz, force 200 Hz; canplayer drives the bus at full rate),
# prints the final parameters and the agreement with the reference, writes the figures
# (OUT_DIR/force.png, OUT_DIR/params.png) and stops the node by its PID.
# Environment: NTE_NODE (default build/host/bin/nte-node, else build/node/bin/nte-node),
#              NTE_DEMO_SPEED (default 1), NTE_DEMO_PLAYER (canplayer | python, default canplayer).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/.." && pwd)"
out="${1:-$repo/out/demo-can}"
mkdir -p "$out"
node="${NTE_NODE:-}"
if [[ -z "$node" ]]; then
    for c in "$repo/build/host/bin/nte-node" "$repo/build/node/bin/nte-node"; do
        [[ -x "$c" ]] && { node="$c"; break; }
    done
fi
[[ -x "$node" ]] || { echo "demo.sh: nte-node not built (cmake --build build/host)" >&2; exit 2; }
py="$repo/.venv/bin/python"; [[ -x "$py" ]] || py=python3

"$py" -m reference_py simulate --preset paper-10mms --depth 50 --dwell 1 --seed 1 \
    --out "$out/insertion.csv" >/dev/null
rm -f "$out/node.ready"
"$node" --iface vcan0 --model 2 --preset paper-10mms --ready "$out/node.ready" \
    --stats "$out/node-stats.json" 2>"$out/node.err" &
node_pid=$!
stop_node() {
    if kill -0 "$node_pid" 2>/dev/null; then
        kill -TERM "$node_pid"
        wait "$node_pid" || true
    fi
}
trap stop_node EXIT
for _ in $(seq 1 100); do [[ -f "$out/node.ready" ]] && break; sleep 0.05; done
[[ -f "$out/node.ready" ]] || { cat "$out/node.err" >&2; echo "demo.sh: node did not start" >&2; exit 1; }
status=0
"$py" -m host_bench.cli replay "$out/insertion.csv" --channel vcan0 \
    --player "${NTE_DEMO_PLAYER:-canplayer}" --speed "${NTE_DEMO_SPEED:-1}" \
    --model 2 --preset paper-10mms --out "$out" || status=$?
stop_node
trap - EXIT
echo "node counters: $(cat "$out/node-stats.json")"
echo "figures: $out/force.png $out/params.png"
exit $status
