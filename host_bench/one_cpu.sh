# one_cpu CMD [ARGS...]: run CMD pinned to one CPU, the first this shell may use (sourced by the
# scripts that play logs onto vcan0).  vcan hands each frame to the receive backlog of the CPU
# its sender is running on.  A sender that moves to another CPU while the first CPU's backlog
# still waits for its softirq (a loaded host, a guest vCPU descheduled) has its later frames
# delivered first: in the fault table's 0.5 s silence row a node read 96 frames after the ones
# that followed them (2-vCPU QEMU guest under load).  From one CPU the frames keep their order.
# Without taskset (util-linux) CMD runs as it is.  Bash builtins only: under QEMU's TCG every
# process started costs some 0.15 s.
one_cpu() {
    local key value cpus=""
    while read -r key value; do
        [[ "$key" == "Cpus_allowed_list:" ]] && cpus="$value"
    done </proc/self/status
    if [[ -n "$cpus" ]] && type -P taskset >/dev/null; then
        taskset -c "${cpus%%[-,]*}" "$@"
    else
        "$@"
    fi
}
