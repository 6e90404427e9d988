#!/usr/bin/env bash
# Build the stable fuzz runner and run every target for FUZZ_SECONDS (default 30) each.
# Exits non-zero on a finding (the input is saved under fuzz/artifacts/<target>/).
#   FUZZ_SECONDS=5 bash fuzz/run.sh                # quicker
#   FUZZ_SEED=7 bash fuzz/run.sh --target mpc      # another seed, one target
# Shares the workspace's target/ so the dependencies the main build compiled are reused.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$here/../target}"
cargo build --quiet --release --manifest-path "$here/Cargo.toml" --bin run
exec "$CARGO_TARGET_DIR/release/run" --seconds "${FUZZ_SECONDS:-30}" --seed "${FUZZ_SEED:-13}" "$@"
