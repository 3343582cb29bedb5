#!/usr/bin/env bash
# `simulate --json` of every scene and hard case under both models, and of the four CARL traces,
# one file each (stdout; stderr and exit status beside it), so that two builds can be compared
# byte for byte after a change that must not change behaviour:
#   scripts/simulate-all.sh BIN OUTDIR        e.g. target/release/handblocks /tmp/after
#   diff -r /tmp/before /tmp/after && echo identical
# Needs ../shared/data/carl beside the checkout for the traces (skipped without it).
set -uo pipefail
if [ $# -ne 2 ]; then
    echo "usage: scripts/simulate-all.sh HANDBLOCKS_BINARY OUTDIR" >&2
    exit 2
fi
bin=$(realpath "$1"); out=$2
mkdir -p "$out"; out=$(realpath "$out")
cd "$(dirname "$0")/.."
for s in config/scenes/*.toml config/scenes/hard/*.toml; do
    n=$(echo "$s" | tr / _)
    for m in paper precise; do
        timeout 300 "$bin" simulate "$s" --model $m --json >"$out/$n.$m.json" 2>"$out/$n.$m.err"
        echo "rc=$?" >>"$out/$n.$m.err"
    done
done
carl=../shared/data/carl
for k in lift pull push settle; do
    [ -f "$carl/example_${k}_0.carl" ] || { echo "skipped: $carl/example_${k}_0.carl" >&2; continue; }
    for m in paper precise; do
        timeout 300 "$bin" simulate config/scenes/carl-$k.toml --hand "$carl/example_${k}_0.carl" \
            --hand-offset 0,-0.92,0 --model $m --json >"$out/carl-$k.$m.json" 2>"$out/carl-$k.$m.err"
        echo "rc=$?" >>"$out/carl-$k.$m.err"
    done
done
echo "$(ls "$out"/*.json | wc -l) outputs in $out"
