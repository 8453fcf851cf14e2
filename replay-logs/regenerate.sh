#!/usr/bin/env bash
# Regenerates the curated replay logs and their truth files from the analytic scenes in
# config/scenes (deterministic: same simulator, same seeds, same bytes). Run from anywhere:
#   bash replay-logs/regenerate.sh
# tests/replay_logs.rs fails when a committed log differs from what this produces.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"
cargo build --release --quiet
sfs=target/release/sfs
# name            scene        device       profile  seed
while read -r name scene device profile seed; do
    "$sfs" simulate --scene "$scene" --device "$device" --profile "$profile" --seed "$seed" \
        --out "replay-logs/$name"
done <<'LIST'
cone-morphorider              cone        morphorider default 1
sphere-octa-morphorider-field sphere-octa morphorider field   2
bowl-phone                    bowl        phone       default 3
LIST
# A sensor array on the bending riser (monitoring mode, with config/riser.toml): one 60 s swing.
"$sfs" simulate --structure riser --duration 60 --seed 1 --out replay-logs/riser-array
