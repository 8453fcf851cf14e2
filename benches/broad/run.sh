#!/usr/bin/env bash
# Scores sfs's phone-mode orientation filter, Fusion and VQF on the BROAD recordings in
# ../shared/data/broad (see BENCHMARKS.md). Installs numpy, scipy, imufusion and vqf from PyPI
# into target/broad-venv.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
venv="$root/target/broad-venv"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/pip" install -q numpy scipy imufusion vqf
cargo build --release --quiet --manifest-path "$root/Cargo.toml" --example ahrs_stream
"$venv/bin/python" "$root/benches/broad/broad.py" --data "${BROAD_DATA:-$root/../shared/data/broad}" \
    --sfs "$root/target/release/examples/ahrs_stream" --json "$root/target/broad.json"
