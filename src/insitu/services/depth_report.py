"""The report of ``insitu depth``: ``depth.json`` and a depth map picture per measured pocket,
written as one folder (replaced as a whole, or left as it was on a failure)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from insitu.formats.atomic import atomic_folder, atomic_write_text
from insitu.services.depth import PassDepth, PocketDepth
from insitu.services.engrave_report import depth_picture, depth_pictures


def write_report(folder: Path, pockets: list[PocketDepth], tolerance_mm: float,
                 source: str, method: str) -> None:
    """``folder``: ``depth.json`` (each pocket's outline, depth, 1σ, stated, floor lines and
    points, why a depth is not stated whatever its σ, or why not measured; on a crossed scan
    also each pass's, and which pass alone measured it and why) and ``pocket-K.png``, the depth map of each measured pocket K (from
    1; on a crossed scan one map per measured pass, side by side)."""
    rows = []
    with atomic_folder(folder) as tmp:
        for k, p in enumerate(pockets, start=1):
            row = {"pocket": p.name, "outline": np.round(
                np.asarray(p.region.exterior.coords)[:-1], 4).tolist()}
            if p.map is None:
                row["refused"] = p.refused
            else:
                picture = f"pocket-{k}.png"
                _picture(tmp / picture, p)
                row |= {"depth_mm": round(p.mean_mm, 6), "sigma_mm": round(p.sem_mm, 6),
                        "stated": p.stated, "floor_lines": p.floor_lines,
                        "floor_points": p.floor_points,
                        "not_floor_points": sum(m.not_floor for m in p.maps),
                        "picture": picture}
            if p.note is not None:
                row["note"] = p.note
            if p.passes:
                row["passes"] = [_pass_row(q) for q in p.passes]
            rows.append(row)
        atomic_write_text(tmp / "depth.json", json.dumps(
            {"scan": source, "method": method, "tolerance_mm": tolerance_mm,
             "pockets": rows}, indent=2) + "\n")


def _pass_row(q: PassDepth) -> dict:
    row = {"pass": q.line_pass.number, "line_angle_deg": round(q.line_pass.angle_deg, 2),
           "lines": int(len(q.line_pass.lines))}
    if q.map is None:
        return row | {"refused": q.refused}
    row |= {"depth_mm": round(q.mean_mm, 6), "sigma_mm": round(q.sem_mm, 6),
            "floor_lines": q.map.floor_lines, "floor_points": len(q.map.floor),
            "combined": q.combined}
    return row if q.note is None else row | {"note": q.note}


def _picture(path: Path, p: PocketDepth) -> None:
    """The pocket's depth map; on a crossed scan each measured pass's, titled with its depth,
    under the combined one."""
    head = f"pocket {p.name}: {p.mean_mm * 1e3:.1f} ± {p.sem_mm * 1e3:.1f} µm (1σ)"
    if not p.passes:
        depth_picture(path, p.map, p.mean_mm, head, centre="mean")
        return
    done = [q for q in p.passes if q.map is not None]
    used = [q for q in done if q.combined]
    whence = "passes combined" if len(used) > 1 else f"pass {used[0].line_pass.number} alone"
    depth_pictures(path, [(q.map, p.mean_mm, f"{q.line_pass.describe()}: "
                           f"{q.mean_mm * 1e3:.1f} ± {q.sem_mm * 1e3:.1f} µm"
                           f"{'' if q.combined else ', not combined'}")
                          for q in done], f"{head}, {whence}", centre="mean")
