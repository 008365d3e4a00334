#!/usr/bin/env bash
# The main job on the simulated rig: scan the step block, write the cloud, print a summary.
# Usage: scripts/demo.sh [OUT_DIR]   (default: ./demo-out)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/setup.sh"
OUT="${1:-$ROOT/demo-out}"
mkdir -p "$OUT"
insitu sim record scan --workpiece step-block -o "$OUT/step-block-scan"
insitu scan --replay "$OUT/step-block-scan" -o "$OUT/step-block.ply" --preview "$OUT/step-block.png"
