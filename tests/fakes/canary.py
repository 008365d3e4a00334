"""A native library that proves whether it was loaded: its constructor (run by the dynamic
loader the moment the library is loaded, before any function is called) creates a file; and a
project whose rig file names it as the RTC library."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

from insitu.formats.calibration import CameraCalibration
from insitu.formats.json_file import save_json_model
from insitu.formats.rig import ScanHeadConfig
from insitu.formats.sequence import Sequence

RECORDED = Path(__file__).parents[1] / "data" / "scan-step-block-b4"

SOURCE = r"""
#include <stdio.h>
__attribute__((constructor)) static void loaded(void) {
    FILE *f = fopen(MARKER, "w");
    if (f) { fputs("loaded\n", f); fclose(f); }
}
"""


def build(folder: Path, name: str = "libcanary.so") -> tuple[Path, Path]:
    """Compile the canary into ``folder``; returns (library, the file its loading creates)."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise RuntimeError("no C compiler (install gcc and libc6-dev: scripts/setup.sh does)")
    src, lib, marker = folder / "canary.c", folder / name, folder / f"{name}.loaded"
    src.write_text(SOURCE)
    subprocess.run([cc, "-shared", "-fPIC", "-o", str(lib), f'-DMARKER="{marker}"', str(src)],
                   check=True, capture_output=True)
    return lib, marker


def project_naming(folder: Path, library: Path) -> tuple[Path, Path]:
    """A project naming a rig file whose RTC library is ``library``; (project, rig file)."""
    rig_dir = folder / "rig"
    rig_dir.mkdir()
    camera = CameraCalibration(camera=Sequence.open(RECORDED).camera)
    save_json_model(rig_dir / "camera.json", camera)
    save_json_model(rig_dir / "head.json", ScanHeadConfig(
        pivot_height_mm=350.0, mirror_distance_mm=350.0, mirror_separation_mm=12.0,
        field_size_mm=(200.0, 200.0), z_range_mm=(-25.0, 25.0)))
    (rig_dir / "head3d.ct5").write_bytes(b"\0" * 16)
    rig = rig_dir / "rig.json"
    rig.write_text(json.dumps({
        "kind": "rig", "camera": "opencv", "scan_head": "rtc", "stage": "none",
        "camera_calibration": "camera.json", "scan_head_config": "head.json",
        "options": {"camera": {"source": "frames/%05d.png"},
                    "rtc": {"library": os.path.relpath(library, rig_dir),
                            "correction_file": "head3d.ct5", "k_bits_per_mm": 2000.0}}}))
    project = folder / "part.insitu.json"
    project.write_text(json.dumps({"format": "insitu-project/1", "schema_version": 1,
                                   "rig": {"rig_file": "rig/rig.json"}}))
    return project, rig
