"""Locate on a recording our code did not draw (``shared/recordings/step-block-independent``:
another renderer, 16 of the 61 scan lines over the step block, mirror images of the line in
the step faces in 5 frames): the scan replayed with Method 2 from its own recorded plate, then
``insitu locate`` against the step block's mesh (what ``insitu sim export-part step-block``
writes). truth.json is read only to score.

Rows: the whole recording; the ICP's pose alone (the edge step off); the recording cut to the
block's half y < 0 (a partial scan); the recording reconstructed with the paper's centres and
height model (where ghosts pass). A pose refused as not pinned down is scored all the same
(x, y, turn against the truth: what would have been marked on). Also how many points of the
ghost frames' lines lie off the true surface (a ghost that reached the cloud) and how far the
edge samples scatter about each step edge (what the edge step works from).

The recording has no room-light frame, but its frames' median (each pixel lit by the line in
at most one of the 16) is one: the block under that renderer's room light. The last rows
give it to locate as the frame, and fit its edges alone from the truth: as locate does, and
with the limit on their scatter lifted through the given and the true camera (scored only).

Run: .venv/bin/python benchmarks/locate_independent.py [RECORDINGS_DIR]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.formats.camera_spec import CameraSpec
from insitu.formats.pointcloud import PointCloud
from insitu.formats.sequence import Sequence
from insitu.geometry.pose import pose_matrix
from insitu.locate.edge_align import edge_samples
from insitu.locate.image_edges import MAX_SPREAD_MM, align_image
from insitu.locate.part import LocateRefused, locate_part
from insitu.locate.reference import above_table, find_table, reference_from_mesh
from insitu.services import calibrate_height, scan_replay
from insitu.services.common import camera_model
from insitu.services.height import scan_camera
from insitu.services.locate import locate_cloud
from insitu.sim.workpieces import make_workpiece
from insitu.vision.extract import PAPER_SETTINGS

DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "recordings"


def median_frame(scan: Path) -> np.ndarray:
    """(H, W) the recording's frames' per-pixel median: the laser lines taken away."""
    seq = Sequence.open(scan)
    frames = np.stack([image for _, _, image in seq])
    return np.median(frames, axis=0).astype(frames.dtype)


def measure(root: Path, paper: bool = False) -> tuple[PointCloud, dict, list[float]]:
    """The replayed cloud (ours, or with ``paper`` the paper's centres and height model: no
    window where the line can be, so a ghost may pass), the truth, the x of the ghost frames'
    lines."""
    scan = root / "step-block-independent"
    truth = json.loads((scan / "truth.json").read_text())
    hcal = root / "height-calibration-coarse-independent"
    cloud = (scan_replay(scan, calibrate_height(hcal, PAPER_SETTINGS), "paper") if paper
             else scan_replay(scan, calibrate_height(hcal)))
    ghosts = {f["file"] for f in truth["frames"] if f.get("ghost")}
    xs = [f.line.start[0] for f in Sequence.open(scan).frames if f.file in ghosts]
    return cloud.cloud, truth, xs


def off_surface(part, cloud: PointCloud, xs: list[float]) -> tuple[int, int]:
    """Points > 0.5 mm off the true surface, ≥ 1 mm from a wall: (on the lines at ``xs``,
    on all lines)."""
    pts = cloud.points
    z = np.nan_to_num(part.height(pts[:, 0], pts[:, 1]))
    wall = np.zeros(len(pts), bool)
    for dy in (-1.0, 1.0):
        wall |= np.abs(np.nan_to_num(part.height(pts[:, 0], pts[:, 1] + dy)) - z) > 0.3
    off = (np.abs(pts[:, 2] - z) > 0.5) & ~wall
    lines = cloud.attributes["line"]
    on = np.zeros(len(pts), bool)
    for i in np.unique(lines):
        sel = lines == i
        on[sel] = np.min(np.abs(np.median(pts[sel, 0]) - np.asarray(xs))) < 0.3
    return int((off & on).sum()), int(off.sum())


def outcome(fn) -> tuple[str, object, object]:
    """("located" or "refused (reason)", the pose's best solution or the refused one (None:
    none), the refusal's message)."""
    try:
        return "located", fn().best, ""
    except LocateRefused as e:
        return f"refused ({e.reason})", e.best, str(e)


def edge_scatter(cloud: PointCloud) -> tuple[int, list[tuple[float, float]]]:
    """The scan's edge samples and, per step edge of the block (samples within 1.5 mm of
    y = −40, −20, 0, 20, 40), the rms and largest |residual| about a line fitted to them,
    mm: how well the lines measure an edge on these frames."""
    pts, lines = cloud.points, cloud.attributes["line"]
    up = above_table(pts, find_table(pts, 0.5), 0.5)
    e = edge_samples(pts, lines, ~up).points
    out = []
    for y in (-40, -20, 0, 20, 40):
        sel = np.abs(e[:, 1] - y) < 1.5
        if sel.sum() >= 3:
            A = np.column_stack([e[sel, 0], np.ones(sel.sum())])
            r = e[sel, 1] - A @ np.linalg.lstsq(A, e[sel, 1], rcond=None)[0]
            out.append((float(np.sqrt(np.mean(r**2))), float(np.abs(r).max())))
    return len(e), out


def main() -> None:
    root = Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT
    cloud, truth, ghost_x = measure(root)
    p = truth["workpiece"]["params"]
    true_part = make_workpiece("step-block", length=p["y_size"], width=p["x_size"],
                               heights=p["heights"], x=p["center"][0], y=p["center"][1])
    mesh = make_workpiece("step-block")
    ref = reference_from_mesh(mesh.vertices, mesh.triangles, "step-block")
    pts = cloud.points
    ghost_off, all_off = off_surface(true_part, cloud, ghost_x)
    paper, _, _ = measure(root, paper=True)
    paper_ghost, paper_all = off_surface(true_part, paper, ghost_x)
    console = Console(width=160)
    console.print(f"{len(pts):,} points, {len(np.unique(cloud.attributes['line']))} lines; "
                  f"mesh {mesh.bounds()} vs truth {true_part.bounds()}")
    console.print(f"points > 0.5 mm off the true surface away from walls, on the ghost lines "
                  f"(x = {', '.join(f'{x:g}' for x in ghost_x)}) / on all: ours "
                  f"{ghost_off} / {all_off}; the paper's centres and model {paper_ghost} / "
                  f"{paper_all}")
    n, scatter = edge_scatter(cloud)
    console.print(f"{n} edge samples; about each step edge's fitted line rms "
                  + ", ".join(f"{r:.3f}" for r, _ in scatter) + " mm, largest "
                  + ", ".join(f"{m:.3f}" for _, m in scatter) + " mm")
    t = Table(title="locate on the independent step-block recording (truth: x 0, y 0, 0°); "
                    "refused poses shown as refused, for scoring")
    for col in ("case", "outcome", "x mm", "y mm", "turn °", "edges", "1σ turn °",
                "fitness", "coverage", "why"):
        t.add_column(col)
    half = pts[:, 1] < 0
    scan = root / "step-block-independent"
    frame = median_frame(scan)
    camera = scan_camera(None, calibrate_height(root / "height-calibration-coarse-independent"))
    cases = (
        ("whole recording", lambda: locate_cloud(ref, cloud)),
        ("ICP only (no edge step)", lambda: locate_part(ref, pts)),
        ("half the block (y < 0)", lambda: locate_part(ref, pts[half],
                                                        lines=cloud.attributes["line"][half])),
        ("the paper's centres and model", lambda: locate_cloud(ref, paper)),
        ("whole, the frames' median as room light",
         lambda: locate_cloud(ref, cloud, camera=camera, image=frame)),
    )
    for name, fn in cases:
        what, b, why = outcome(fn)
        if b is None:
            t.add_row(name, what, "", "", "", "", "", "", "", why)
        else:
            t.add_row(name, what, f"{b.x_mm - p['center'][0]:+.3f}",
                      f"{b.y_mm - p['center'][1]:+.3f}", f"{b.angle_deg:+.3f}", str(b.edges),
                      "" if b.sigma_deg is None else f"{b.sigma_deg:.3f}",
                      f"{b.fitness:.1%}", f"{b.coverage:.1%}", why)
    console.print(t)
    true_camera = camera_model(CameraSpec.model_validate(truth["camera_true"]))
    for name, cam, spread in (("given", camera, MAX_SPREAD_MM), ("given", camera, 1.0),
                              ("true", true_camera, 1.0)):
        fit = align_image(frame, cam, ref.heights, ref.outline, pose_matrix(*p["center"], 0.0),
                          spread)
        what = fit if isinstance(fit, str) else (
            f"x {fit.xy_mm[0] - p['center'][0]:+.3f}, y {fit.xy_mm[1] - p['center'][1]:+.3f} "
            f"mm, turn {np.degrees(fit.angle_rad):+.3f}° (1σ {fit.sigma_deg:.3f}°), "
            f"{fit.edges} edge points, scatter {fit.rms_mm:.3f} mm")
        console.print(f"the frames' median alone, its edges fitted from the truth through the "
                      f"{name} camera, scatter up to {spread:g} mm: {what}")


if __name__ == "__main__":
    main()
