"""What a scan reference gives locating: its outline fitted from its own room-light frame and
its lines (:mod:`insitu.locate.outline_fit`), how much of it they show and how well lines and
circles fit it — with what to do where it falls short (``insitu recipe new`` reports it)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from insitu.errors import ConfigError
from insitu.locate.outline_fit import GRAZING_DEG, checked, floor_of
from insitu.locate.part import SIGMAS
from insitu.locate.reference import PartReference
from insitu.locate.uncertainty import outline_hold

COVERED_BELOW = 0.5
"""The frame shows less of the outline than this: a warning."""
AGREE_MM = 0.05
"""The frame's edges and the lines' ends further apart than this on an edge: a warning."""


def scan_reference(reference: Path, room_light: Path | None,
                   height_cal: Path | None) -> PartReference:
    """The scan ``reference`` with its outline fitted from ``room_light`` (a frame of the
    camera of ``height_cal``; ConfigError when the frame comes without it)."""
    from insitu.services.common import camera_model
    from insitu.services.height import load_height_calibration
    from insitu.services.locate import load_reference

    if room_light is not None and height_cal is None:
        raise ConfigError("--reference-room-light needs --height-cal: the frame's edges are "
                          "placed through the camera the reference was scanned with")
    camera = (None if height_cal is None else
              camera_model(load_height_calibration(height_cal).camera))
    return load_reference(reference, room_light=room_light, camera=camera)


def outline_findings(ref: PartReference, tolerance: tuple[float, float] = (0.05, 0.1)
                     ) -> list[tuple[str, str, str]]:
    """(level "info" | "warning", label, text) of a scan reference's outline; ``tolerance``
    (mm at the rim, 2σ; degrees of the turn, 3σ): what a located pose is held to."""
    fit = ref.fitted
    if fit is None:
        return [("warning", "outline", "its scan lines' ends only (0.15–0.3 mm out beside "
                 "walls): give the reference's room-light frame (--reference-room-light), or "
                 "a CAD mesh, for parts to be placed within 0.05 mm")]
    kinds = [p.kind for p in fit.pieces]
    worst = max(fit.pieces, key=lambda p: p.rms_mm)
    offsets = [abs(p.offset_mm) for p in fit.pieces if math.isfinite(p.offset_mm)]
    crossed = fit.length_mm(crossed=True) / max(fit.length_mm(), 1e-9)
    sigma = fit.outline.sigma_mm
    out = [("info", "outline", f"{kinds.count('line')} straight and {kinds.count('circle')} "
            f"round edges, {fit.length_mm():.1f} mm; the frame shows {fit.covered:.0%} of "
            "the scan's outline"),
           ("info", "fit", f"edge points within {worst.rms_mm:.3f} mm (rms, worst edge) of "
            f"their line or circle; each edge placed to 1σ {sigma.min():.3f}–{sigma.max():.3f} "
            "mm (its fit, its light's bias; more where the crossed scan's lines do not check "
            "it or the camera sees its top at a grazing angle)"),
           ("info", "lines", f"{crossed:.0%} of it crossed from two directions; the frame's "
            "edges " + (f"within {max(offsets):.3f} mm of where the lines end" if offsets
                        else "not crossed by the lines"))]
    out.append(("info", "edges", _edges(fit.pieces)))
    out += _holds(ref, tolerance)
    if fit.covered < COVERED_BELOW:
        out.append(("warning", "coverage", f"the frame shows only {fit.covered:.0%} of the "
                    "outline (walls seen edge-on, tops alike): light the part so its edges "
                    "stand out, or use a CAD mesh"))
    grazing = [p for p in fit.pieces if p.view_deg >= GRAZING_DEG]
    if grazing:
        out.append(("info", "grazing", f"{len(grazing)} edge(s) whose top the camera sees at "
                    f"{min(p.view_deg for p in grazing):.0f}° or more from its normal (a top "
                    "falling away from it): placed to 1σ 0.1 mm or more, their lines' ends not "
                    "trusted"))
    if crossed < 0.5:
        out.append(("warning", "crossed", "scan the reference crossed (insitu scan --cross): "
                    "its lines cross too little of the outline from two directions"))
    if offsets and max(offsets) > AGREE_MM:
        out.append(("warning", "agreement", f"the frame and the lines disagree by up to "
                    f"{max(offsets):.3f} mm on an edge: its parts will be located less "
                    "precisely (or refused)"))
    return out


def _edges(pieces) -> str:
    """Each edge of a fitted outline: its length (mm), its points' scatter about it and its 1σ
    across it (µm); * not checked by the crossed scan's lines, "ends": fitted to them."""
    out = []
    for p in sorted(pieces, key=lambda p: -p.length_mm):
        sigma = math.hypot(floor_of(p)[0], p.sigma_mm)
        out.append(f"{p.kind} {p.length_mm:.0f} / {1000 * p.rms_mm:.0f} / {1000 * sigma:.0f}"
                   + ("*" if not checked(p) else "") + (" ends" if p.source == "scan" else ""))
    return ("each edge, length mm / scatter / 1σ across µm (* not checked by the lines, "
            "ends: fitted to the lines' ends): " + ", ".join(out))


def _holds(ref: PartReference, tolerance: tuple[float, float]) -> list[tuple[str, str, str]]:
    """What the outline pins (:func:`insitu.locate.uncertainty.outline_hold`): x, y and the
    turn, each to its 1σ; a warning naming the direction it cannot hold to ``tolerance``."""
    o = ref.fitted.outline
    h = outline_hold(o.points[:, :2], o.normals, o.points[:, 2], o.sigma_mm, o.tilt_mm,
                     ref.rim)
    out = [("info", "pins", f"its edges alone hold a part along x to {h.x_mm:.3f} mm, along "
            f"y to {h.y_mm:.3f} mm, its turn to {h.turn_deg:.3f}° (1σ; {h.rim_mm:.3f} mm at "
            "its rim), before the later frame's own errors")]
    short = []
    if SIGMAS * h.rim_mm > tolerance[0]:
        reach = float(np.linalg.norm(ref.rim - ref.rim.mean(axis=0), axis=1).max())
        weakest = ("its turn" if np.radians(h.turn_deg) * reach > max(h.x_mm, h.y_mm) else
                   "along " + ("x" if abs(h.weakest[0]) >= abs(h.weakest[1]) else "y"))
        short.append(f"{SIGMAS:g}σ at the rim {SIGMAS * h.rim_mm:.3f} mm > {tolerance[0]:g} "
                     f"mm (weakest {weakest}: the edges that fix it short, unlit or not "
                     "crossed by the lines)")
    if 3 * h.turn_deg > tolerance[1]:
        short.append(f"3σ of the turn {3 * h.turn_deg:.3f}° > {tolerance[1]:g}° (its "
                     "straight edges too short to fix the turn)")
    if short:
        out.append(("warning", "pinned", "parts located against it will be refused: "
                    + "; ".join(short) + ": a CAD mesh of the part, or a reference scanned "
                    "crossed under a clearer light, would pin it"))
    return out
