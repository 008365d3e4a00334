#!/usr/bin/env bash
# The main job on the simulated rig: calibrate the heights on the flat plate, scan the step
# block, reconstruct it (Method 2, our light-sheet model), write the cloud and a picture, print
# a summary. Usage: scripts/demo.sh [OUT_DIR]   (default: ./demo-out)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/setup.sh"
OUT="${1:-$ROOT/demo-out}"
mkdir -p "$OUT"
[ -f "$OUT/height.json" ] || {
    insitu sim record height-calibration -o "$OUT/height-cal"
    insitu calibrate height "$OUT/height-cal" -o "$OUT/height.json"
}
insitu sim record scan --workpiece step-block -o "$OUT/step-block-scan"
insitu scan --replay "$OUT/step-block-scan" --height-cal "$OUT/height.json" \
    -o "$OUT/step-block.ply" --preview "$OUT/step-block.png"
