#!/usr/bin/env bash
# The README's pictures of the station's window (docs/gui.png: the top view with camera
# colours; docs/gui-iso.png: the iso view by height), rendered under Xvfb from the recorded
# step block at binning 2 with a QR code placed on its 10 mm step.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-.venv/bin/python}
QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1280x1024x24" "$PY" -m insitu.ui.qt.screenshot \
    docs/gui.png --replay tests/data/scan-step-block-b2 --height-cal tests/data/height-cal-b2.json \
    --binning 2 --pattern 'qr:"SN 0042"' --at 0 10 --width 8 --view top --camera-colours \
    --ambient-from-rig --extra iso:height:docs/gui-iso.png
