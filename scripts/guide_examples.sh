#!/usr/bin/env bash
# The user guide's worked example on the own-rig files, run as the guide writes it, each
# command's output kept:
#
#     bash scripts/guide_examples.sh OUT
#
# copies examples/own-rig and examples/bench into OUT/examples (the repository's examples stay
# as they are), runs there, in order, the commands of docs/guide/rig.md (synth, calibrate),
# docs/guide/predict.md (predict with --sets 10 --placements 4) and docs/guide/design.md (design
# with --sets 6 --placements 3), and writes each command's terminal output to
# OUT/NN-COMMAND.txt, with OUT's own path written as OUT (a machine's path stays out of them).
# The tables the guide shows come from these files.
set -euo pipefail
out=${1:?usage: bash scripts/guide_examples.sh OUT}
root=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$out/examples"
cp -r "$root/examples/own-rig" "$root/examples/bench" "$out/examples/"
cd "$out"
here=$(pwd)
export COLUMNS=110
run() {
    local name=$1
    shift
    echo "\$ $*" | tee "$name.txt"
    local t0=$SECONDS
    "$@" 2>&1 | sed "s#$here#OUT#g" | tee -a "$name.txt"
    echo "(wall time $((SECONDS - t0)) s)" | tee -a "$name.txt"
}
run 01-synth parcelfit synth examples/own-rig/twin-spec.yaml --out examples/own-rig/data
run 02-calibrate parcelfit calibrate examples/own-rig/study.yaml
run 03-predict parcelfit predict examples/own-rig/study --rig examples/own-rig/D1.yaml \
    --consignment examples/own-rig/envelope.yaml --speed-setting 2 --sets 10 --placements 4
run 04-design parcelfit design examples/own-rig/study --rig examples/bench/B1.yaml \
    --candidate B1/envelope/1 --candidate D1/envelope/2 --sets 6 --placements 3
