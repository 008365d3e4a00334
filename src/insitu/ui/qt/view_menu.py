"""The View menu of the main window: the preset views (keys 1–4; the top view orthographic),
the Orthographic toggle, Frame all (F or Home), Camera colours (C: the cloud coloured by the
ambient camera frame instead of by height; disabled, saying why, for a cloud without that
frame), and every dock and the toolbar, to show one again after it was closed."""

from __future__ import annotations

from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import QMenu, QToolBar

NO_AMBIENT = ("this cloud has no camera picture: it was measured without an ambient "
              "(laser-off) frame")
NO_CLOUD = "no point cloud: scan or open one"


class ViewMenu:
    """Fills ``menu`` and keeps its toggles in step with the view and the session."""

    def __init__(self, menu: QMenu, window):
        view, binding, session = window.view, window.binding, window.session
        self.view, self.binding, self.session = view, binding, session
        menu.setToolTipsVisible(True)
        parent = window

        def action(text, slot, keys=(), checkable=False) -> QAction:
            a = QAction(text, parent)
            a.setShortcuts([QKeySequence(k) for k in keys])
            a.setCheckable(checkable)
            (a.toggled if checkable else a.triggered).connect(slot)
            menu.addAction(a)
            return a

        for name, key in (("top", "1"), ("front", "2"), ("side", "3"), ("iso", "4")):
            action(f"{name.capitalize()} view", lambda _=False, n=name: view.set_view(n), [key])
        menu.addSeparator()
        self.ortho = action("Orthographic", view.set_ortho, ["O"], checkable=True)
        self.ortho.setChecked(view.camera.ortho)
        view.projection_changed.connect(self.ortho.setChecked)
        self.frame = action("Frame all", lambda: binding.frame_all(), ["F", "Home"])
        self.camera_colours = action("Camera colours", view.set_camera_colours, ["C"],
                                     checkable=True)
        menu.addSeparator()
        docks = menu.addMenu("&Docks")
        for dock in window.docks.values():
            docks.addAction(dock.toggleViewAction())
        for bar in window.findChildren(QToolBar):
            docks.addAction(bar.toggleViewAction())
        session.cloud_changed.connect(self.update_state)
        session.live_points_added.connect(lambda _p: self.update_state())
        self.update_state()

    def update_state(self) -> None:
        """Camera colours only for a cloud that has them; the tooltip says why not."""
        ok = self.view.has_camera_colours
        a = self.camera_colours
        a.setEnabled(ok)
        cloud = self.session.cloud
        a.setToolTip("colour each point by the camera's ambient (laser-off) frame (C)" if ok
                     else NO_CLOUD if cloud is None or len(cloud) == 0 else NO_AMBIENT)
        self.view.set_camera_colours(ok and a.isChecked())
