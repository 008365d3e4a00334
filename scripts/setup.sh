#!/usr/bin/env bash
# Sourced by demo.sh and test.sh: installs what is missing, quickly when nothing is.
# Debian system libraries (open3d: libusb; Qt/OpenGL tests: Xvfb + Mesa; Qt's xcb platform, which
# the OpenGL test and `insitu gui` on a desktop use: libxcb-*; the fake RTC library that the
# device tests compile: gcc, libc6-dev; cairosvg, which renders SVG paints: libcairo2; fc-match,
# which finds an SVG's fonts: fontconfig), then .venv with insitu, its GUI and the test tools
# (INSITU_EXTRAS, default gui,test,test-gui; scripts/test-core.sh makes .venv-core without the GUI).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${INSITU_VENV:-$ROOT/.venv}"
EXTRAS="${INSITU_EXTRAS:-gui,test,test-gui}"

need_pkgs=()
for pkg in libusb-1.0-0 gcc libc6-dev xvfb xauth libgl1 libegl1 libgl1-mesa-dri libglx-mesa0 \
           libxkbcommon0 libxkbcommon-x11-0 libfontconfig1 libdbus-1-3 fonts-dejavu-core \
           libx11-xcb1 libxcb-cursor0 libxcb-glx0 libxcb-icccm4 libxcb-image0 libxcb-keysyms1 \
           libxcb-randr0 libxcb-render-util0 libxcb-shape0 libxcb-xfixes0 libxcb-xkb1 \
           libglib2.0-0 libcairo2 fontconfig; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || need_pkgs+=("$pkg")
done
if ((${#need_pkgs[@]})); then
    echo "insitu setup: installing ${#need_pkgs[@]} system packages with apt-get (sudo; about a" \
         "minute): ${need_pkgs[*]}"
    SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${need_pkgs[@]}" >/dev/null
fi

PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null || PY=python3
if [ ! -x "$VENV/bin/python" ]; then
    echo "insitu setup: creating $VENV"
    "$PY" -m venv "$VENV"
fi
STAMP="$VENV/.insitu-installed"
if [ ! -f "$STAMP" ] || [ "$ROOT/pyproject.toml" -nt "$STAMP" ] || [ "$(cat "$STAMP")" != "$EXTRAS" ]; then
    PKGS="$("$VENV/bin/python" - "$ROOT/pyproject.toml" "$EXTRAS" <<'PY'
import re, sys, tomllib
project = tomllib.load(open(sys.argv[1], "rb"))["project"]
extras = [e for e in sys.argv[2].split(",") if e]
deps = project["dependencies"] + [d for e in extras for d in project["optional-dependencies"][e]]
print(", ".join(re.split(r"[<>=!~;\[ ]", d, maxsplit=1)[0] for d in deps))
PY
)"
    echo "insitu setup: installing insitu[$EXTRAS] into $VENV with pip (the first time a" \
         "minute or two): $PKGS"
    LOG="$VENV/pip-install.log"
    if ! "$VENV/bin/python" -m pip install -e "$ROOT[$EXTRAS]" >"$LOG" 2>&1; then
        tail -n 30 "$LOG" >&2
        echo "insitu setup: pip install failed (full log: $LOG)" >&2
        exit 1
    fi
    echo "$EXTRAS" >"$STAMP"
    echo "insitu setup: installed (pip's log: $LOG)"
fi
export PATH="$VENV/bin:$PATH"
