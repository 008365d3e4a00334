#!/usr/bin/env bash
# Regenerates the committed recordings of tests/data from the simulator (fixed seeds).
set -euo pipefail
cd "$(dirname "$0")"
insitu sim record scan --workpiece step-block --binning 4 --spacing 1.0 --seed 11 -o scan-step-block-b4
insitu sim record height-calibration --binning 4 --seed 11 -o height-cal-b4
insitu sim record scan --workpiece step-block --spacing 6.0 --region -6 6 -46 46 --seed 11 -o scan-step-block-full
