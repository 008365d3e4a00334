"""The Production dock: a recipe marked on part after part (``insitu produce``) — the recipe,
Start / Stop, the current part's cloud in the 3-D view with the located reference's outline
over it (nothing else of the session drawn), the read-back picture and the log as a table
whose rows say a refusal's reason in words (the whole of it in their tooltip). File ▸ Save
as recipe turns the session's cloud (the part's first scan) and placements into a
``.recipe.json``, once the cloud shows the part's whole top
(:mod:`insitu.services.reference_check`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PySide6.QtCore import QObject, Qt, Signal
from PySide6.QtGui import QImage, QPixmap
from PySide6.QtWidgets import (
    QCheckBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QSpinBox,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from insitu.errors import InsituError

COLUMNS = (("part", "part"), ("outcome", "outcome"), ("reason", "error"), ("serial", "serial"),
           ("x mm", "x_mm"), ("y mm", "y_mm"), ("angle °", "angle_deg"),
           ("fitness", "fitness"), ("decoded", "decoded"), ("grade", "grade"),
           ("offset mm", "offset_mm"))
"""(header, the log record's field) of the table's columns."""
RECIPE_SUFFIX = ".recipe.json"
RECIPE_FILES = f"recipes (*{RECIPE_SUFFIX} *.json)"
OUTLINE_COLOUR = (1.0, 0.55, 0.1, 1.0)


class _Bridge(QObject):
    """Hands the worker thread's records and stages to the GUI thread (queued signals)."""

    record = Signal(object)
    stage = Signal(int, str)


def reference_outline(reference, T_world_part: np.ndarray) -> np.ndarray:
    """Segments (2K, 3) float32 of the reference's outline seen from above (its top points'
    convex hull at their highest z), moved where the part was located."""
    import shapely

    top = reference.top if len(reference.top) else reference.points
    hull = np.asarray(shapely.MultiPoint(top[:, :2]).convex_hull.exterior.coords)
    ring = np.column_stack([hull, np.full(len(hull), top[:, 2].max())])
    world = ring @ np.asarray(T_world_part)[:3, :3].T + np.asarray(T_world_part)[:3, 3]
    return np.repeat(world, 2, axis=0)[1:-1].astype(np.float32)


class ProductionPanel(QWidget):
    def __init__(self, window, parent=None):
        super().__init__(parent)
        self.window_ = window
        self.recipe = None
        self.records = []
        self._reference = None
        self._bridge = _Bridge(self)
        self._bridge.record.connect(self._record)
        self._bridge.stage.connect(lambda k, s: self.status.setText(f"part {k}: {s}…"))
        self.recipeEdit = QLineEdit(placeholderText=f"recipe ({RECIPE_SUFFIX})")
        browse = QPushButton("…", clicked=self._browse)
        self.recipeLabel = QLabel("no recipe", wordWrap=True)
        self.logEdit = QLineEdit(placeholderText="log (.jsonl; default beside the recipe)")
        self.countSpin = QSpinBox(minimum=1, maximum=1_000_000, value=10)
        self.randomCheck = QCheckBox("random poses (simulated rig), seed")
        self.seedSpin = QSpinBox(minimum=0, maximum=2**31 - 1, value=1)
        self.resumeCheck = QCheckBox("resume the log's run")
        self.startButton = QPushButton("Start", clicked=self.start)
        self.stopButton = QPushButton("Stop", clicked=self.stop, enabled=False)
        self.status = QLabel("", wordWrap=True)
        self.readbackImage = QLabel(alignment=Qt.AlignCenter, minimumHeight=120)
        self.readbackLabel = QLabel("", wordWrap=True)
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels([h for h, _ in COLUMNS])
        row = QHBoxLayout()
        row.addWidget(self.recipeEdit, 1)
        row.addWidget(browse)
        form = QFormLayout()
        form.addRow("Recipe", row)
        form.addRow("", self.recipeLabel)
        form.addRow("Log", self.logEdit)
        form.addRow("Parts", self.countSpin)
        seeds = QHBoxLayout()
        seeds.addWidget(self.randomCheck)
        seeds.addWidget(self.seedSpin)
        form.addRow("", seeds)
        form.addRow("", self.resumeCheck)
        buttons = QHBoxLayout()
        buttons.addWidget(self.startButton)
        buttons.addWidget(self.stopButton)
        lay = QVBoxLayout(self)
        for item in (form, buttons):
            lay.addLayout(item)
        for w in (self.status, self.readbackImage, self.readbackLabel, self.table):
            lay.addWidget(w)
        self.recipeEdit.editingFinished.connect(lambda: self.open_recipe(self.recipeEdit.text()))
        window.runner.busy_changed.connect(self._busy)

    def _browse(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open recipe", "", RECIPE_FILES)
        if path:
            self.open_recipe(path)

    def open_recipe(self, path: str | Path) -> bool:
        """Read the recipe (its one-line refusal shown in the panel)."""
        from insitu.formats.recipe import read_recipe
        from insitu.marking import Placement
        from insitu.marking.modes import PROJECTIONS

        self.recipeEdit.setText(str(path))
        try:
            self.recipe = read_recipe(path, Placement, PROJECTIONS)
        except InsituError as e:
            self.recipe = None
            self.recipeLabel.setText(str(e))
            return False
        r = self.recipe
        self.recipeLabel.setText(f"{r.reference.name} ({r.reference_kind}); "
                                 f"{len(r.placements)} placement(s): "
                                 + ", ".join(p.pattern for p in r.placements))
        self._reference = None
        return True

    def log_path(self) -> Path:
        text = self.logEdit.text().strip()
        if text:
            return Path(text)
        path = Path(self.recipeEdit.text())
        return path.with_name(recipe_stem(path) + ".production.jsonl")

    def start(self) -> None:
        """Run the recipe on the connected station, off the GUI thread."""
        from insitu.services import production
        from insitu.services.height import scan_camera
        from insitu.services.locate import recipe_locator
        from insitu.services.part_reading import read_part

        station, r = self.window_.station, self.recipe
        if r is None or station is None:
            self.status.setText("open a recipe and connect the rig first")
            return
        workpiece = r.workpiece or "step-block"
        seed = self.seedSpin.value() if self.randomCheck.isChecked() else None
        present = station.part_feeder(workpiece, seed)
        log, count, resume = self.log_path(), self.countSpin.value(), self.resumeCheck.isChecked()
        self.table.setRowCount(0)
        self.records = []
        self.window_.binding.clear_overlays()
        self.window_.view.set_lines("located", np.zeros((0, 3), np.float32), OUTLINE_COLOUR)
        bridge = self._bridge

        def work(progress, cancel, on_frame):
            cal = self.window_.session.height_cal
            locate = recipe_locator(r, scan_camera(station.rig.camera, cal))
            self._reference = locate.reference
            run = production.Production(
                r, station, log, count, locate, read_part, present,
                cancel=cancel, height_cal=cal,
                on_record=bridge.record.emit, on_stage=bridge.stage.emit)
            return production.produce(run, resume)

        self.window_.runner.start("produce", work, self._done, self._failed)

    def stop(self) -> None:
        """Stop the run: the laser goes off at once, the part is logged as aborted."""
        self.window_.runner.cancel("produce")

    def _busy(self, name: str, busy: bool) -> None:
        if name == "produce":
            self.startButton.setEnabled(not busy)
            self.stopButton.setEnabled(busy)

    def _done(self, records) -> None:
        marked = sum(r.outcome == "marked" for r in records)
        self.status.setText(f"done: {marked} of {len(records)} parts marked; log "
                            f"{self.log_path()}")

    def _failed(self, message: str, cancelled: bool) -> None:
        self.status.setText(("stopped: " if cancelled else "fault: ") + message
                            + " — the laser is off; Start with resume continues")

    def _record(self, rec) -> None:
        """A part's record: a row of the table, its cloud and the located outline in the
        view (nothing else drawn), its read-back picture."""
        from insitu.formats.pointcloud import read_ply
        from insitu.geometry.pose import pose_matrix

        self.records.append(rec)
        d = rec.model_dump()
        row = self.table.rowCount()
        self.table.insertRow(row)
        tip = record_words(rec)
        for col, (_h, key) in enumerate(COLUMNS):
            v = d[key]
            item = QTableWidgetItem("" if v is None else f"{v:.3f}" if isinstance(v, float)
                                    else str(v))
            item.setToolTip(tip)
            self.table.setItem(row, col, item)
        self.table.resizeColumnToContents(COLUMNS.index(("outcome", "outcome")))
        self.table.scrollToBottom()
        folder = self.log_path().parent
        cloud = folder / f"part-{rec.part:04d}.cloud.ply"
        view = self.window_.view
        self.window_.binding.clear_overlays()
        if cloud.exists():
            view.set_cloud(read_ply(cloud).points)
        outline = np.zeros((0, 3), np.float32)
        if rec.x_mm is not None and self._reference is not None:
            outline = reference_outline(self._reference,
                                        pose_matrix(rec.x_mm, rec.y_mm, rec.angle_deg))
        view.set_lines("located", outline, OUTLINE_COLOUR)
        picture = folder / f"part-{rec.part:04d}.readback.png"
        if picture.exists():
            image = QImage(str(picture))
            self.readbackImage.setPixmap(QPixmap.fromImage(image).scaledToWidth(
                max(self.readbackImage.width(), 200), Qt.SmoothTransformation))
        self.readbackLabel.setText(tip)
        self.readbackLabel.setToolTip(tip)


def record_words(rec) -> str:
    """A part's record in words: "part 2, serial 7: marked; read '007' (= plan), grade B,
    offset 0.05 mm" or "part 3: refused — part not found: …"."""
    serial = "" if rec.serial is None else f", serial {rec.serial}"
    text = f"part {rec.part}{serial}: {rec.outcome}"
    if rec.error:
        text += f" — {rec.error}"
    if rec.decoded is not None:
        text += (f"; read {rec.decoded!r} ({'= plan' if rec.decode_ok else 'NOT the plan'}), "
                 f"grade {rec.grade}, offset {rec.offset_mm} mm")
    return text


def recipe_stem(path: Path) -> str:
    """"r" of r.recipe.json (or of r.json)."""
    name = Path(path).name
    for suffix in (RECIPE_SUFFIX, ".json"):
        if name.endswith(suffix):
            return name.removesuffix(suffix)
    return name


def save_session_as_recipe(window, path: Path):
    """The session's cloud (written beside the recipe when it is not on disk) as the part's
    reference and its placements in that cloud's frame, as a recipe at ``path``; returns the
    reference's :class:`~insitu.services.reference_check.ReferenceCheck`. InsituError,
    nothing written, when the cloud cannot serve as the reference (the part cut by the
    scan's edge, too little of its top measured)."""
    from insitu.formats.pointcloud import write_ply
    from insitu.formats.recipe import Recipe, write_recipe
    from insitu.services.reference_check import check_reference

    s = window.session
    if s.cloud is None or not s.placements.items:
        raise InsituError("Save as recipe needs a scanned cloud and at least one placement")
    check = check_reference(s.cloud.points, s.cloud.attributes.get("line"))
    if check.level == "refused":
        raise InsituError(f"{path.name}: not saved: {check.text}")
    reference = s.cloud_path
    if reference is None or not Path(reference).exists():
        reference = path.with_name(recipe_stem(path) + ".reference.ply")
        write_ply(reference, s.cloud)
    write_recipe(path, Recipe(Path(reference).absolute(), "cloud", tuple(s.placements.items),
                              workpiece=s.rig_choice.workpiece
                              if s.rig_choice.rig_file is None else None,
                              serial_start=1))
    return check


def recipe_path(path: str | Path) -> Path:
    """``path`` named as a recipe: ``….recipe.json``."""
    path = Path(path)
    return path if path.name.endswith(RECIPE_SUFFIX) else \
        path.with_name(recipe_stem(path) + RECIPE_SUFFIX)


def save_recipe_dialog(window) -> None:
    """File ▸ Save as recipe…: the reference's check said in the status bar."""
    path, _ = QFileDialog.getSaveFileName(window, "Save as recipe", "", RECIPE_FILES)
    if not path:
        return
    path = recipe_path(path)
    try:
        check = save_session_as_recipe(window, path)
    except InsituError as e:
        window.show_error(str(e), "recipe")
        return
    say = window.show_error if check.level == "warning" else window.show_message
    say(f"saved {path}; {check.text}", "recipe")
