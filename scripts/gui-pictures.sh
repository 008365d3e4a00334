#!/usr/bin/env bash
# The README's pictures of the station's window, rendered under Xvfb: docs/gui.png (the
# orthographic top view with camera colours), docs/gui-iso.png (the iso view by height) and
# every dock, docs/gui-dock-NAME.png (scan, place, mark, calibrate, production, camera).
# The step block is recorded at binning 2 (0.25 mm line spacing, a minute or two) and a QR
# code placed on its 10 mm step; the camera colours come from the recording's laser-off frame
# (ambient.png).
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-.venv/bin}
REC=$(mktemp -d)
trap 'rm -rf "$REC"' EXIT
"$BIN/insitu" sim record scan --workpiece step-block --binning 2 --spacing 0.25 \
    --region -14 14 -46 46 --seed 11 -o "$REC/scan"
QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1280x1024x24" "$BIN/python" -m insitu.ui.qt.screenshot \
    docs/gui.png --replay "$REC/scan" --height-cal tests/data/height-cal-b2.json --binning 2 \
    --pattern 'qr:"SN 0042"' --at 0 10 --width 8 --view top --camera-colours \
    --extra iso:height:docs/gui-iso.png --docks docs
