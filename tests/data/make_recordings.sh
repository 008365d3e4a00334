#!/usr/bin/env bash
# Regenerates the committed recordings of tests/data from the simulator (fixed seeds).
set -euo pipefail
cd "$(dirname "$0")"
insitu sim record scan --workpiece step-block --binning 4 --spacing 1.0 --seed 11 -o scan-step-block-b4
insitu sim record height-calibration --binning 4 --seed 11 --no-cross -o height-cal-b4    # as committed: lines along y only
insitu sim record scan --workpiece step-block --spacing 6.0 --region -6 6 -46 46 --seed 11 -o scan-step-block-full
# binning 2: a few lines over the step block, and the height calibration fitted from a binning-2
# recording (the fitted file only: the recording's 91 frames are 58 MB)
insitu sim record scan --workpiece step-block --binning 2 --spacing 2.0 --region -6 6 -46 46 --seed 11 -o scan-step-block-b2
insitu sim record height-calibration --binning 2 --seed 11 --no-cross -o height-cal-b2
insitu calibrate height height-cal-b2 -o height-cal-b2.json
rm -r height-cal-b2 height-cal-b2.png
