"""Keeps the 3-D view showing the session: the cloud (and its live growth during a scan),
the scan field and region, each pattern as placed (above the part) and as projected (on the
surface, in its pen's colour), and a red cross where a check refused it."""

from __future__ import annotations

import numpy as np

from insitu.errors import InsituError
from insitu.ui.model import scene_data as sd
from insitu.ui.model.session import Session
from insitu.ui.qt.view3d import View3D


class SceneBinding:
    def __init__(self, session: Session, view: View3D):
        self.session, self.view = session, view
        self.top_z = 0.0                    # where unprojected patterns are drawn
        self._live_range: list[float] | None = None
        self._pen_layers: set[str] = set()
        session.cloud_changed.connect(self.show_cloud)
        session.live_points_added.connect(self.add_live_points)
        for sig in (session.placements.changed, session.selection_changed,
                    session.plans_changed, session.pens_changed):
            sig.connect(self.show_patterns)

    def show_field(self, field_size_mm, z_range_mm) -> None:
        """The scan field on z = 0 and the focus range's top and bottom (faint)."""
        hx, hy = np.asarray(field_size_mm, float) / 2
        self.view.set_lines("field", sd.rectangle(-hx, hx, -hy, hy, 0.0), sd.FIELD_COLOUR)
        faint = (*sd.FIELD_COLOUR[:3], 0.25)
        self.view.set_lines("focus", np.concatenate([sd.rectangle(-hx, hx, -hy, hy, z)
                                                     for z in z_range_mm]), faint)

    def show_region(self, region) -> None:
        verts = np.zeros((0, 3)) if region is None else sd.rectangle(*region, 0.0)
        self.view.set_lines("region", verts, sd.REGION_COLOUR)

    def show_cloud(self) -> None:
        cloud = self.session.cloud
        self._live_range = None
        self.view.set_lines("pilot", np.zeros((0, 3)), sd.PILOT_COLOUR)
        if cloud is None or len(cloud) == 0:
            self.view.set_cloud(None)
            return
        pts = cloud.points
        self.view.set_cloud(pts)
        self.top_z = float(np.percentile(pts[:, 2], 99.5)) + 1.0
        self.view.handle_z = self.top_z
        self.view.frame_all(pts.min(0), pts.max(0))
        self.show_patterns()

    def add_live_points(self, points: np.ndarray) -> None:
        z = points[:, 2]
        lo, hi = float(z.min()), float(z.max())
        r = self._live_range
        self._live_range = [lo, hi] if r is None else [min(r[0], lo), max(r[1], hi)]
        self.view.renderer.z_range = tuple(self._live_range)
        self.view.append_points(points)

    def show_patterns(self) -> None:
        s = self.session
        placed, selected, warn = [], [], []
        projected: dict[str, list] = {}                   # pen colour → its paths' segments
        handles = None
        for i, p in enumerate(s.placements.items):
            try:
                lines = sd.pattern_lines(sd.placed_pattern(p), self.top_z)
            except InsituError:
                continue
            (selected if i == s.selected else placed).append(lines)
            if i == s.selected:
                handles = sd.handles(p)
            if i < len(s.plans):
                outcome = s.plans[i]
                if outcome.plan is not None:
                    projected.setdefault(s.pen_of(p).colour, []).append(
                        sd.segments(outcome.plan.projection.paths))
                elif outcome.where is not None:
                    warn.append(self._warning_cross(outcome.where, p.width_mm))
        cat = (lambda a: np.concatenate(a) if a else np.zeros((0, 3), np.float32))
        self.view.set_lines("placed", cat(placed), sd.PLACED_COLOUR)
        self.view.set_lines("selected", cat(selected), sd.SELECTED_COLOUR)
        layers = {f"projected {c}" for c in projected}
        for name in self._pen_layers - layers:
            self.view.set_lines(name, np.zeros((0, 3), np.float32), sd.PROJECTED_COLOUR)
        for colour, segs in projected.items():
            rgb = tuple(int(colour[i:i + 2], 16) / 255 for i in (1, 3, 5))
            self.view.set_lines(f"projected {colour}", cat(segs), (*rgb, 1.0))
        self._pen_layers = layers
        self.view.set_lines("warnings", cat(warn), sd.WARNING_COLOUR)
        self.view.handles = handles

    def _warning_cross(self, xy, width_mm: float) -> np.ndarray:
        """A cross at (x, y) on the cloud (its nearest point's height)."""
        z = self.top_z
        cloud = self.session.cloud
        if cloud is not None and len(cloud):
            d = np.linalg.norm(cloud.points[:, :2] - np.asarray(xy), axis=1)
            z = float(cloud.points[np.argmin(d), 2])
        return sd.cross(xy[0], xy[1], z, max(width_mm / 8, 1.0))
