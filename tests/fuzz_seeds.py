"""Valid seed files of every reader the fuzzing engine (tests/fuzzing.py) mutates, and how each
is read and first used: PLY ascii and binary, a recording's sequence.json and its PNG frame,
rig file, height calibration, field correction, job, project, pens, SVG, DXF (``READERS``)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from insitu.calibrate.field_file import FieldCorrection, load_field_correction
from insitu.formats.calibration import HeightCalibration
from insitu.formats.json_file import load_json_model, save_json_model
from insitu.formats.pens import DEFAULT_PENS, read_pens, write_pens
from insitu.formats.pointcloud import PointCloud, read_ply, write_ply
from insitu.formats.project import Project, RigChoice, ScanSettings, read_project, write_project
from insitu.formats.rig import RigConfig
from insitu.formats.sequence import Sequence
from insitu.formats.sequence_writer import SequenceWriter
from insitu.geometry.beams import TwoMirrorHead
from insitu.marking import (
    PROJECTIONS,
    GalvoDriver,
    LaserOverride,
    Placement,
    make_job,
    read_job,
    write_job,
)
from insitu.patterns.dxf import load_dxf
from insitu.patterns.svg import load_svg
from insitu.services.height import height_model
from insitu.vision.extract import CentreSettings

HEAD = TwoMirrorHead(350.0, 12.0)
CAMERA = {"width": 32, "height": 24, "K": [[40.0, 0, 16.0], [0, 40.0, 12.0], [0, 0, 1]],
          "dist": [0.01, 0, 0, 0, 0], "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0, 0, 300.0]}
SCAN_HEAD = {"lens": "non-telecentric", "pivot_height_mm": 350.0, "field_size_mm": [200, 200],
             "z_range_mm": [-25.0, 25.0]}
# -------------------------------------------------------------------------- seed files
def _job():
    """Two paths, the second with a pen's settings (passes, delays, wobble)."""
    return make_job([np.array([[0.0, 0.0, 0.0], [5.0, 1.0, 0.5]]),
                     np.array([[-3.0, 2.0, 1.0], [-3.0, 6.0, 1.0], [1.0, 6.0, 1.0]])],
                    overrides={1: LaserOverride.of_pen(DEFAULT_PENS.pen("bold").model_copy(
                        update={"passes": 2}))})


def _finite(pattern) -> None:
    for line in pattern.contours + pattern.paths:
        if not np.isfinite(line).all():
            raise AssertionError("non-finite coordinates accepted")


def _cloud(folder: Path, ascii: bool) -> tuple[Path, Callable]:
    import open3d as o3d

    pts = np.random.default_rng(0).uniform(-5, 5, (24, 3))
    path = folder / "cloud.ply"
    if ascii:
        pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(pts))
        pcd.point["intensity"] = o3d.core.Tensor(np.linspace(0, 1, 24, dtype=np.float32)[:, None])
        o3d.t.io.write_point_cloud(str(path), pcd, write_ascii=True)
    else:
        write_ply(path, PointCloud(pts, {"intensity": np.linspace(0, 1, 24),
                                         "line": np.arange(24)}))
    return path, read_ply


def _recording(folder: Path) -> Path:
    rec = folder / "rec"
    img = (np.arange(24 * 32).reshape(24, 32) % 251).astype(np.uint8)
    with SequenceWriter(rec, "scan", SCAN_HEAD, CAMERA) as w:
        w.add(img, line={"start": [0.0, -10.0], "end": [0.0, 10.0]})
        w.add(img[::-1].copy(), line={"start": [2.0, -10.0], "end": [2.0, 10.0]})
    return rec


def _read_recording(rec: Path) -> None:
    seq = Sequence.open(rec)
    for _ in seq:
        pass


def _sequence(folder: Path):
    rec = _recording(folder)
    return rec / "sequence.json", lambda p: _read_recording(p.parent)


def _frame(folder: Path):
    rec = _recording(folder)
    return rec / "frames" / "00000.png", lambda p: _read_recording(p.parents[1])


def _rig(folder: Path):
    path = folder / "rig.json"
    path.write_text(json.dumps({"kind": "rig", "camera": "opencv", "scan_head": "rtc",
                                "stage": "grbl", "camera_calibration": "camera.json",
                                "options": {"rtc": {"library": "librtc6.so",
                                                    "k_bits_per_mm": 2000.0}}}))

    def read(p):
        c = load_json_model(p, RigConfig)
        c.resolve(c.camera_calibration)
    return path, read


def _height(folder: Path):
    path = folder / "height.json"
    sheet = {"pivot_height_mm": 350.0, "exponents": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
             "coefficients_mm": [0.0, 1.0, 0.5], "scale_mm": [100.0, 100.0, 50.0],
             "x_range_mm": [-50.0, 50.0], "z_range_mm": [-20.0, 20.0]}
    save_json_model(path, HeightCalibration(camera=CAMERA, centres=CentreSettings().to_dict(),
                                            sheet=sheet))

    def read(p):
        camera, model = height_model(load_json_model(p, HeightCalibration))
        model.points(camera, 0.0, np.array([10.0, 16.0]), np.array([12.0, 3.0]))
    return path, read


def _field(folder: Path):
    path = folder / "field.json"
    save_json_model(path, FieldCorrection(
        method="table", field_size_mm=(200.0, 200.0), region_mm=[-50.0, 50.0, -50.0, 50.0],
        table={"x_nodes_mm": [-50.0, 0.0, 50.0], "y_nodes_mm": [-50.0, 0.0, 50.0],
               "values_mm": [[[0.1, 0.0]] * 3] * 3}))
    return path, lambda p: load_field_correction(p).correct(np.array([[0.0, 0.0], [20.0, -10.0]]))


def _job_file(folder: Path):
    path = folder / "job.json"
    write_job(path, _job())
    return path, lambda p: GalvoDriver(HEAD).compile(read_job(p))


def _project(folder: Path):
    (folder / "height.json").write_text("{}")
    (folder / "logo.svg").write_text("<svg/>")
    (folder / "part.ply").write_text("ply")
    path = folder / "p.insitu.json"
    write_project(path, Project(
        RigChoice("step-block", 3, 4), folder / "height.json",
        scan=ScanSettings((-10.0, 10.0, -40.0, 40.0), 0.25, 8.0, speed_mm_s=1500.0),
        cloud=folder / "part.ply",
        placements=(Placement(str(folder / "logo.svg"), (1.0, 2.0), 12.0, 15.0, "wrap", 0.1,
                              45.0, True), Placement('text:"x"', (0.0, 0.0), 5.0, pen="deep")),
        selected=1, pens=DEFAULT_PENS))
    return path, lambda p: read_project(p, Placement, PROJECTIONS)


def _pens(folder: Path):
    path = folder / "pens.json"
    write_pens(path, DEFAULT_PENS)
    return path, read_pens


def _svg(folder: Path):
    path = folder / "logo.svg"
    path.write_text(
        "<svg xmlns='http://www.w3.org/2000/svg' width='40mm' height='30mm' viewBox='0 0 40 30'>"
        "<g transform='translate(2 3) rotate(10)'><path d='M 1 1 C 5 0 8 4 10 10 Q 12 14 6 16 "
        "A 4 3 20 0 1 2 12 Z' fill='black'/><rect x='14' y='2' width='8' height='5' "
        "stroke='black' stroke-width='0.8' fill='none'/></g><circle cx='30' cy='20' r='4' "
        "fill='#222'/><polyline points='1,25 8,28 15,24' stroke='black' stroke-width='0.1' "
        "fill='none'/><ellipse cx='30' cy='8' rx='5' ry='2' fill='white' stroke='black' "
        "stroke-width='0.02'/></svg>")
    return path, lambda p: _finite(load_svg(p))


def _dxf(folder: Path):
    import ezdxf

    doc = ezdxf.new()
    doc.header["$INSUNITS"] = 4
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0), (10, 0), (10, 5), (0, 5)], close=True)
    msp.add_circle((20, 20), 3)
    msp.add_arc((0, 20), 4, 10, 200)
    msp.add_line((-5, -5), (5, 8))
    msp.add_ellipse((30, 0), (4, 1, 0), ratio=0.5)
    msp.add_spline([(0, 0), (3, 4), (6, -1), (9, 3)])
    msp.add_hatch().paths.add_polyline_path([(40, 0), (45, 0), (45, 5)])
    path = folder / "part.dxf"
    doc.saveas(path)
    return path, lambda p: _finite(load_dxf(p))


# name: (make the seed in a folder → (file to mutate, read it), how to mutate it)
READERS: dict[str, tuple[Callable, str]] = {
    "ply-ascii": (lambda f: _cloud(f, True), "text"),
    "ply-binary": (lambda f: _cloud(f, False), "ply"),
    "sequence": (_sequence, "json"),
    "png-frame": (_frame, "png"),
    "rig": (_rig, "json"),
    "height-calibration": (_height, "json"),
    "field-correction": (_field, "json"),
    "job": (_job_file, "json"),
    "project": (_project, "json"),
    "pens": (_pens, "json"),
    "svg": (_svg, "text"),
    "dxf": (_dxf, "text"),
}
