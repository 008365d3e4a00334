"""Planning a mark: each placement loaded, placed, projected on the measured surface and checked,
with one verdict per placement — the plan, or the refusal — and every finding the operator
must see (the loader's warnings, what a step leaves unmarked, whether a code reads from the
planned marks, a quiet zone entered, the cloud measured on another rig). ``insitu mark``,
``insitu mark --recipe``, production and the application's Place and Mark docks all plan
through :func:`plan_placements`, so the same placement gets the same verdict everywhere."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from insitu.errors import FormatError, InsituError, SafetyError
from insitu.formats.pens import DEFAULT_PENS, PenTable
from insitu.formats.pointcloud import PointCloud
from insitu.marking import (
    GalvoDriver,
    LaserParams,
    MarkJob,
    Placement,
    Projection,
    TimeEstimate,
    estimate_time,
    plan_job,
    with_pen,
)
from insitu.marking.modes import PROJECTIONS
from insitu.marking.verify import CodeCheck, check_code, unrolled
from insitu.patterns import Pattern

if TYPE_CHECKING:
    from insitu.services.station import Station

Level = Literal["refused", "warning", "info"]


@dataclass(frozen=True)
class Finding:
    """One check of a placement as the operator reads it: ``level``; ``check``, what was
    checked ("pattern", "surface", "walls", "code", "quiet zone", "rig"); ``text``, one line;
    ``where_mm``, the place (world x, y) when the check knows one."""

    level: Level
    check: str
    text: str
    where_mm: tuple[float, float] | None = None

    def line(self) -> str:
        """``refused: …``, ``warning: …`` or the text alone."""
        return self.text if self.level == "info" else f"{self.level}: {self.text}"


@dataclass(frozen=True)
class MarkPlan:
    """A checked job and how it came about: ``pattern`` placed (world x, y before
    projection), ``projection`` (support, stretch), ``estimate`` of the marking time,
    ``codes``: whether each code reads from the job's marks."""

    job: MarkJob
    pattern: Pattern
    projection: Projection
    estimate: TimeEstimate
    codes: tuple[CodeCheck, ...] = ()


@dataclass(frozen=True)
class PlanOutcome:
    """The verdict on one placement: ``plan`` when it passed every check (None: refused) and
    its ``findings``, refusals first."""

    plan: MarkPlan | None = None
    findings: tuple[Finding, ...] = ()

    @classmethod
    def refused(cls, check: str, text: str, where_mm=None,
                findings: Sequence[Finding] = ()) -> PlanOutcome:
        return cls(None, (Finding("refused", check, text, where_mm), *findings))

    @property
    def error(self) -> str | None:
        """The first refusal's one line (None: not refused)."""
        return next((f.text for f in self.findings if f.level == "refused"), None)

    @property
    def where(self) -> tuple[float, float] | None:
        """The first refusal's place (None: not refused, or no place known)."""
        return next((f.where_mm for f in self.findings if f.level == "refused"), None)

    @property
    def warnings(self) -> list[str]:
        return [f.text for f in self.findings if f.level == "warning"]

    def lines(self) -> list[str]:
        """Every finding as one line, refusals first, then warnings, then the rest."""
        order = {"refused": 0, "warning": 1, "info": 2}
        return [f.line() for f in sorted(self.findings, key=lambda f: order[f.level])]


def check_codes(job: MarkJob, pattern: Pattern, projection: Projection,
                beam_mm: float) -> tuple[CodeCheck, ...]:
    """Decode the code of ``pattern`` (if any) from the job's marks: their x, y, or unrolled
    along the surface when the projection has an unroll direction (wrap)."""
    if pattern.code is None or pattern.frame is None:
        return ()
    paths3d = [p.points for p in job.paths]
    if projection.direction_deg is not None and projection.anchor is not None:
        paths_xy = unrolled(paths3d, projection.anchor, projection.direction_deg)
    else:
        paths_xy = [p[:, :2] for p in paths3d]
    return (check_code(pattern, paths_xy, beam_mm)[0],)


def _findings(placement: Placement, plan: MarkPlan, force: bool) -> list[Finding]:
    """What the operator must see of a plan that passed the surface checks."""
    out = [Finding("warning" if n.startswith("warning:") else "info", "pattern",
                   n.removeprefix("warning: ")) for n in plan.pattern.notes]
    proj = plan.projection
    if proj.unmarked_mm > 0:
        out.append(Finding("warning", "walls", f"unmarked at walls {proj.unmarked_mm:.2f} mm of "
                           f"{proj.path_mm:.0f} mm of path ({proj.unmarked_fraction:.1%}): across "
                           "a wall and where the cloud does not show where it is"))
    for c in plan.codes:
        if c.ok:
            out.append(Finding("info", "code", f"decodes yes: {c.name} (module "
                                               f"{c.module_mm:.3g} mm)"))
            continue
        wall = (f", {proj.unmarked_fraction:.1%} of its path left unmarked at a step's wall: "
                "place it off the step" if proj.unmarked_mm > 0 else "")
        if force:
            out.append(Finding("warning", "code", f"decodes NO: {c.name} (module "
                               f"{c.module_mm:.3g} mm, read {c.decoded!r}{wall}); marked as "
                               "forced"))
        else:
            out.append(Finding("refused", "code", f"{c.name}: does not decode from the planned "
                               f"marks (read {c.decoded!r}, module {c.module_mm:.3g} mm{wall}); "
                               "nothing written"))
    if PROJECTIONS[placement.mode].stretches:
        out.append(Finding("info", "projection", f"{placement.mode}, worst stretch "
                                                 f"{proj.max_stretch:.2%}"))
    return out


def check_placement(cloud: PointCloud, placement: Placement, driver: GalvoDriver,
                    laser: LaserParams | None = None, force: bool = False,
                    pens: PenTable | None = None) -> PlanOutcome:
    """Place, project and check one placement: refused (with the place when known) for a
    pattern outside the field or focus range, over a hole or a wall, whose corrected commands
    leave the field, a bad pattern or pen, or a code that would not decode from the planned
    marks (a warning instead with ``force``). With ``pens`` (or a placement naming a pen: then
    of :data:`DEFAULT_PENS`) every path carries its pen's settings. Nothing is written or
    fired."""
    try:
        pen = None
        if pens is not None or placement.pen is not None:
            pen = (pens or DEFAULT_PENS).pen(placement.pen, f"placement {placement.pattern}")
        pattern = placement.placed()
        polylines = placement.polylines(pattern)
        job, proj = plan_job(polylines, cloud, driver.limits, placement.mode, laser,
                             anchor=placement.at_mm)
        job = job.model_copy(update={"rig": cloud.rig})     # the job records the cloud's rig
        if pen is not None:
            job = with_pen(job, pen)
        driver.check(job)
    except SafetyError as e:
        return PlanOutcome.refused("surface", str(e), e.where_mm)
    except InsituError as e:
        return PlanOutcome.refused("pattern", str(e))
    plan = MarkPlan(job, pattern, proj, estimate_time(job, driver.timing),
                    check_codes(job, pattern, proj, placement.beam_mm))
    findings = tuple(_findings(placement, plan, force))
    refused = any(f.level == "refused" for f in findings)
    return PlanOutcome(None if refused else plan, findings)


def plan_mark(cloud: PointCloud, placement: Placement, driver: GalvoDriver,
              laser: LaserParams | None = None, force: bool = False,
              pens: PenTable | None = None) -> MarkPlan:
    """The plan of :func:`check_placement`, or its refusal raised (:func:`raise_refusal`)."""
    return raise_refusal(check_placement(cloud, placement, driver, laser, force, pens))


def plan_placements(cloud: PointCloud, placements: Sequence[Placement], driver: GalvoDriver,
                    laser: LaserParams | None = None, pens: PenTable | None = None,
                    force: bool = False, rig: Finding | None = None) -> list[PlanOutcome]:
    """:func:`check_placement` of each placement. A code whose quiet zone another placement's marks
    enter is refused, and so is the placement whose marks enter it (each naming the other,
    the place where they meet). ``rig``: the station's check of the cloud's rig
    (:meth:`insitu.services.station.Station.rig_finding`), added to every verdict."""
    out = _quiet_zones_clear([check_placement(cloud, p, driver, laser, force, pens)
                              for p in placements])
    if rig is None:
        return out
    return [PlanOutcome(None if rig.level == "refused" else o.plan, (rig, *o.findings))
            for o in out]


def raise_refusal(outcome: PlanOutcome, what: str = "") -> MarkPlan:
    """The plan of ``outcome``, or its first refusal raised as the error that refused it
    (SafetyError with its place for the surface and the rig, FormatError otherwise),
    prefixed by ``what``; the error's ``warnings`` are the outcome's warning lines."""
    if outcome.plan is not None:
        return outcome.plan
    f = next(f for f in outcome.findings if f.level == "refused")
    e = (SafetyError(what + f.text, f.where_mm) if f.check in ("surface", "rig") else
         FormatError(what + f.text))
    e.warnings = tuple(what + w for w in outcome.warnings)
    raise e


def joined(outcomes: Sequence[PlanOutcome], laser: LaserParams | None = None) -> MarkJob:
    """One job marking every planned placement in order (its ``laser`` when given); the first
    refusal raised (naming its placement) when any was refused."""
    for i, o in enumerate(outcomes):
        if o.plan is None:
            raise_refusal(o, f"placement {i + 1}: " if len(outcomes) > 1 else "")
    if not outcomes:
        raise FormatError("nothing to mark: no placement")
    job = outcomes[0].plan.job.model_copy(update={"paths": [path for o in outcomes
                                                             for path in o.plan.job.paths]})
    return job if laser is None else job.model_copy(update={"laser": laser})


def _quiet_zones_clear(outcomes: list[PlanOutcome]) -> list[PlanOutcome]:
    """``outcomes`` with a refusal for each code whose frame — symbol and quiet zone —
    another planned pattern's marks (world x, y, as placed) reach into, and for that
    pattern."""
    import shapely

    out = list(outcomes)
    marks = [None if o.plan is None else shapely.union_all(
        [o.plan.pattern.to_shapely(), *map(shapely.LineString, o.plan.pattern.paths)])
        for o in outcomes]
    for i, o in enumerate(outcomes):
        code = None if o.plan is None else o.plan.pattern
        if code is None or code.code is None or code.frame is None:
            continue
        zone = shapely.Polygon(code.frame)
        for j, m in enumerate(marks):
            if j == i or m is None or not m.intersects(zone):
                continue
            c = m.intersection(zone).representative_point()
            out[i] = PlanOutcome.refused("quiet zone", f"{code.name}: placement {j + 1}'s marks "
                                         "enter its quiet zone (a reader needs it clear)",
                                         (c.x, c.y), outcomes[i].findings)
            if out[j].plan is not None:
                out[j] = PlanOutcome.refused(
                    "quiet zone", f"{outcomes[j].plan.pattern.name}: its marks enter the quiet "
                    f"zone of placement {i + 1} ({code.name})", (c.x, c.y), outcomes[j].findings)
            break
    return out


def rig_finding(station: Station, source: Path | str, record) -> Finding | None:
    """The station's check of a cloud's rig record (:meth:`Station.check_source`) before
    marking on it: another rig or workpiece is refused, a cloud without a record is a
    warning, None when it is this station's."""
    try:
        warning = station.check_source(Path(source), record, "cloud")
    except SafetyError as e:
        return Finding("refused", "rig", str(e))
    return None if warning is None else Finding("warning", "rig", warning)
