"""Keeps the 3-D view showing the session: the cloud (and its live growth during a scan;
with the camera's ambient gray when it has one), the scan field and region, each pattern
once — its projected paths on the surface in its pen's colour when it has a plan, else as
placed, above the part — and a red cross where a check refused it; frames the cloud and the
patterns."""

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
        ambient = cloud.attributes.get(sd.AMBIENT)
        if ambient is not None and len(ambient) != len(pts):
            ambient = None
        self.view.set_cloud(pts, ambient=ambient)
        self.top_z = float(np.percentile(pts[:, 2], 99.5)) + 1.0
        self.view.handle_z = self.top_z
        self.show_patterns()
        self.frame_all()

    def bounds(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(lo, hi) (3,) mm of the cloud and the placed patterns' outlines, or None."""
        boxes = []
        cloud = self.session.cloud
        if cloud is not None and len(cloud):
            boxes += [cloud.points.min(0), cloud.points.max(0)]
        for p in self.session.placements.items:
            try:
                c = sd.handles(p).corners
            except InsituError:
                continue
            boxes += [np.c_[c, np.full(4, self.top_z)].min(0), np.c_[c, np.zeros(4)].max(0)]
        if not boxes:
            return None
        b = np.vstack(boxes)
        return b.min(0), b.max(0)

    def frame_all(self) -> bool:
        """Fit the cloud and the patterns into the view; False when there is nothing."""
        box = self.bounds()
        if box is not None:
            self.view.frame_all(*box)
        return box is not None

    def add_live_points(self, points: np.ndarray) -> None:
        z = points[:, 2]
        lo, hi = float(z.min()), float(z.max())
        r = self._live_range
        self._live_range = [lo, hi] if r is None else [min(r[0], lo), max(r[1], hi)]
        self.view.renderer.z_range = tuple(self._live_range)
        self.view.append_points(points)

    def show_patterns(self) -> None:
        """Each pattern once: its projected paths where it will be marked when it has a
        plan (the selected one's handles and outline at their height), else as placed."""
        s = self.session
        placed, selected, warn = [], [], []
        projected: dict[str, list] = {}                   # pen colour → its paths' segments
        handles, handle_z = None, self.top_z
        for i, p in enumerate(s.placements.items):
            outcome = s.plans[i] if i < len(s.plans) else None
            paths = None if outcome is None or outcome.plan is None else \
                outcome.plan.projection.paths
            if i == s.selected:
                try:
                    handles = sd.handles(p)
                except InsituError:
                    continue
            if paths is not None:
                projected.setdefault(s.pen_of(p).colour, []).append(sd.segments(paths))
                if i == s.selected and len(outcome.plan.projection.points):
                    handle_z = float(np.median(outcome.plan.projection.points[:, 2]))
                continue
            try:
                lines = sd.pattern_lines(sd.placed_pattern(p), self.top_z)
            except InsituError:
                continue
            (selected if i == s.selected else placed).append(lines)
            if outcome is not None and outcome.where is not None:
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
        self.view.renderer.shade = sd.SHADE_UNDER_PENS if projected else 1.0
        self.view.set_lines("warnings", cat(warn), sd.WARNING_COLOUR)
        self.view.handles = handles
        self.view.handle_z = handle_z
        self.view.update()

    def clear_overlays(self) -> None:
        """Nothing of the session drawn over the view's cloud (a production part's): no
        pattern, handle, warning or pilot outline, until the session changes."""
        empty = np.zeros((0, 3), np.float32)
        for name in ("placed", "selected", "warnings", "pilot", *self._pen_layers):
            self.view.set_lines(name, empty, sd.PLACED_COLOUR)
        self._pen_layers = set()
        self.view.handles = None
        self.view.update()

    def _warning_cross(self, xy, width_mm: float) -> np.ndarray:
        """A cross at (x, y) on the cloud (its nearest point's height)."""
        z = self.top_z
        cloud = self.session.cloud
        if cloud is not None and len(cloud):
            d = np.linalg.norm(cloud.points[:, :2] - np.asarray(xy), axis=1)
            z = float(cloud.points[np.argmin(d), 2])
        return sd.cross(xy[0], xy[1], z, max(width_mm / 8, 1.0))
