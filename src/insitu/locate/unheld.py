"""Which way a scan's edges leave a part free: when the edge step (:mod:`insitu.locate.
edge_align`) finds no fit at a pose, the direction its samples hold least and the sentence
that says so (which edges would hold it).
"""

from __future__ import annotations

import numpy as np

from insitu.geometry.pose import rot_z
from insitu.locate.edge_align import (
    MIN_COS,
    MIN_FOUND,
    MIN_SAMPLES,
    crossed,
    edge_distance,
    near_edges,
)
from insitu.locate.height_image import HeightImage


def unheld(heights: HeightImage, e: np.ndarray, u: np.ndarray
           ) -> tuple[int, np.ndarray | None]:
    """Why :func:`align_edges` may find no fit at this pose: the edge samples ``e`` (K, 3),
    part frame, directions ``u`` (K, 2), that find the reference's edge, and the unit
    direction (2,) part frame of the shift their edges hold least, with the inset (the
    least eigenvector of Σ [n, −ν][n, −ν]ᵀ / K; None: no sample found). Edges that all
    face one way leave the shift along them free; edges facing two ways alone leave it free
    along their bisector, where moving the part and insetting both edges alike look the
    same (a triangle whose third side runs along the lines, a corner of two sides)."""
    s, n = edge_distance(heights, e, u)
    nu = np.einsum("ij,ij->i", n, u)
    ok = np.isfinite(s) & (nu > MIN_COS)
    if not ok.any():
        return 0, None
    J = np.column_stack([n[ok], -nu[ok]])
    d = np.linalg.eigh(J.T @ J / ok.sum())[1][:2, 0]
    return int(ok.sum()), d / max(float(np.linalg.norm(d)), 1e-12)


def unheld_reason(heights: HeightImage, e: np.ndarray, u: np.ndarray,
                  angle_rad: float) -> tuple[str, np.ndarray | None]:
    """Why the edges give no fit at a pose, and the direction (2,) part frame they hold
    least (None: too few samples to say): too few of the scan's edge samples (``e``, ``u``
    in the part's frame) lie by the reference's edges, or those found leave a direction
    free (named in the world frame; ``angle_rad``: the world → part turn)."""
    found, free = unheld(heights, e, u)
    near = near_edges(heights, e, u, np.zeros(2), 0.0, np.zeros(2))
    if found < MIN_SAMPLES or near < MIN_FOUND * len(e):
        return (f"{found} of the scan's {len(e)} edge samples find the reference's edges "
                f"along their lines and {near} lie by one (at least {MIN_SAMPLES} and "
                f"{MIN_FOUND:.0%} needed)"), None
    name, faces = direction_name(rot_z(-angle_rad)[:2, :2] @ free)   # part frame → world
    return (f"the {found} edge samples the scan lines give hold the part along {faces} "
            f"only: nothing holds it along {name}; turn the part or the scan, or scan "
            f"crossed, so that lines cross an edge facing "
            f"{name if name[0] == '(' else '±' + name}"), free


def direction_name(d: np.ndarray) -> tuple[str, str]:
    """A world direction (2,) named ("x", "y" or its components) and the edges across it
    ("±y", "±x", …)."""
    near = np.cos(np.radians(20))
    return (("x", "±y") if abs(d[0]) > near else ("y", "±x") if abs(d[1]) > near
            else (f"({d[0]:+.2f}, {d[1]:+.2f})", f"({-d[1]:+.2f}, {d[0]:+.2f})"))


def pin_advice(kind: str, lines: np.ndarray | None, points: np.ndarray,
            framed: bool) -> str:
    """What would pin a pose down, as a sentence: a crossed pass (unless the scan's
    ``lines`` (N,) of ``points`` (N, 3) cross), the room-light frame (unless ``framed``), a
    CAD reference (unless the reference's ``kind`` is "mesh"), finer lines."""
    if lines is None:
        return "what would pin it down: a cloud with its scan lines (insitu scan writes them)"
    out = []
    if not crossed(points, np.asarray(lines)):
        out.append("a crossed pass (scan --cross)")
    if not framed:
        out.append("the room-light frame (--room-light with --height-cal)")
    if kind != "mesh":
        out.append("a CAD reference (a mesh of the part)")
    out.append("finer lines (spacing, binning)")
    return "what would pin it down: " + ", ".join(out)
