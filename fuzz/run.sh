#!/usr/bin/env bash
# Build the stable fuzz runner and run every target for FUZZ_SECONDS (default 30) each.
# Exits non-zero on a finding (the input is saved under fuzz/artifacts/<target>/).
#   FUZZ_SECONDS=5 bash fuzz/run.sh                # quicker
#   FUZZ_SEED=7 bash fuzz/run.sh --target mpc      # another seed, one target
#   FUZZ_JOBS=2 bash fuzz/run.sh                   # the targets split over two processes
# Shares the workspace's target/ so the dependencies the main build compiled are reused.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$here/../target}"
cargo build --quiet --release --manifest-path "$here/Cargo.toml" --bin run
run="$CARGO_TARGET_DIR/release/run"
opts=(--seconds "${FUZZ_SECONDS:-30}" --seed "${FUZZ_SEED:-13}")
jobs="${FUZZ_JOBS:-1}"
if [ "$jobs" -le 1 ] || [ "$#" -gt 0 ]; then
    exec "$run" "${opts[@]}" "$@"
fi
# Processes, not threads: the runner's watchdog and allocation cap are process-wide. Each
# takes every jobs-th target; a target's inputs do not depend on which process runs it.
mapfile -t targets < <("$run" --list)
logs="$(mktemp -d)"
pids=()
for ((j = 0; j < jobs; j++)); do
    args=()
    for ((i = j; i < ${#targets[@]}; i += jobs)); do
        args+=(--target "${targets[$i]}")
    done
    [ "${#args[@]}" -gt 0 ] || continue
    "$run" "${opts[@]}" "${args[@]}" > "$logs/$j" 2>&1 &
    pids+=($!)
done
status=0
for p in "${pids[@]}"; do
    wait "$p" || status=1
done
cat "$logs"/*
rm -rf "$logs"
exit "$status"
