#!/usr/bin/env bash
# Issue 33: which commit of the field-accuracy work changed each validation capture. Builds each
# commit in a worktree (one target directory shared, so only the changed crates build again),
# replays the captures with it and scores them with this checkout's `sfs eval`.
#
#   bash benches/validation_bisect.sh [COMMIT ...]     (default: the field-accuracy commits)
#
# Needs ../shared/validation beside the repository and a release build of this checkout
# (target/release/sfs). About 1.5 minutes a commit on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
V=${VALIDATION_DIR:-../shared/validation}
WORK=${BISECT_DIR:-/tmp/sfs-validation-bisect}
EVAL="$PWD/target/release/sfs"
CAPTURES="lilium-morphorider-rough-s21 bumpy-cube-morphorider-rough-s21 saddle-morphorider-rough-s21 bumpy-cube-phone-s21 lilium-phone-s21 saddle-phone-s21 ellipsoid-phone-s21"
COMMITS=${*:-baa97be 7b2f2ae 1e7efc9 6178151 09b5817 17c25e1 f2e0b67 e46f02c 6360e05 3f9b563 dd9b107 1b493a8}
mkdir -p "$WORK"
echo "| commit | ${CAPTURES// / | } |"
for c in $COMMITS; do
    rm -rf "$WORK/wt"
    git worktree add -f --detach "$WORK/wt" "$c" >/dev/null 2>&1
    (cd "$WORK/wt" && CARGO_TARGET_DIR="$WORK/target" cargo build --release --bin sfs >"$WORK/build-$c.log" 2>&1)
    line="| $c |"
    for cap in $CAPTURES; do
        rm -rf "$WORK/out"
        "$WORK/target/release/sfs" replay "$V/$cap.bin" --out "$WORK/out" >/dev/null 2>&1 || true
        e=$("$EVAL" eval --truth "$V/$cap.truth.json" --glb "$WORK/out/network.glb" 2>/dev/null |
            python3 -c "import json,sys; print('%.3f' % json.load(sys.stdin)['curves']['mean_pct'])" 2>/dev/null || echo failed)
        line="$line $e |"
    done
    echo "$line"
    git worktree remove --force "$WORK/wt"
done
