"""When a located pose is given and when refused, and the words of a refusal
(:func:`insitu.locate.part.locate_part`'s steps 4 and 6): the best of the distinct solutions
is chosen or refused as absent, partial, ambiguous or not preferred (:func:`choose`), then
given only when its σ puts it within the tolerance (:func:`pinned`); every refusal names the
numbers and what would pin the pose down.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from insitu.errors import MeasurementError
from insitu.locate.search import Solution
from insitu.locate.unheld import direction_name

if TYPE_CHECKING:
    from insitu.locate.part import LocateSettings

SIGMAS = 2.0
"""A pose is given when this many σ at the part's rim lie within the tolerance."""


class LocateRefused(MeasurementError):
    """The part's pose is not given: ``reason`` is "no-part", "poor-fit", "partial",
    "ambiguous" or "not-preferred"; the message names the numbers; ``best``: the pose that
    was refused as not pinned down (None otherwise), for scoring."""

    def __init__(self, reason: str, message: str, best: Solution | None = None):
        super().__init__(message)
        self.reason = reason
        self.best = best


def margin(sol: Solution, s: LocateSettings) -> float:
    """How much of the tolerance and of the turn's bound a pose's σ takes (≤ 1: given)."""
    turn = sol.turn_sigma_deg
    return max(SIGMAS * sol.rim_sigma_mm / s.tolerance_mm, 3 * turn / s.turn_bound_deg,
               0.0 if s.turn_tolerance_deg is None else SIGMAS * turn / s.turn_tolerance_deg)


def slid(a: Solution, b: Solution) -> str | None:
    """How two poses that fit alike differ by a shift alone (turned less than 2° apart):
    the direction nothing holds, or None when they are turned apart (a symmetric part)."""
    if abs((a.angle_deg - b.angle_deg + 180.0) % 360.0 - 180.0) >= 2.0:
        return None
    d = np.array([b.x_mm - a.x_mm, b.y_mm - a.y_mm])
    name, _ = direction_name(d / max(float(np.linalg.norm(d)), 1e-12))
    return (f"{a.describe()} and {b.describe()} fit nearly equally, "
            f"{float(np.linalg.norm(d)):.2f} mm apart along {name}: nothing holds the part "
            f"along {name}" + ("" if a.sigma_mm is not None else
                               " (the cloud records no scan lines: no edge step)"))


def _in_range(angle: float, lo: float, hi: float) -> bool:
    return (angle - lo) % 360.0 <= (hi - lo) % 360.0 or (hi - lo) >= 360.0


def choose(sols: list[Solution], n: int, where: str, s: LocateSettings,
           prefer: tuple[float, float] | None, framed=None
           ) -> tuple[Solution, Solution | None]:
    """(best, second) or LocateRefused. ``framed``: the best refined by the room-light
    frame's edges (``_imaged`` of :mod:`insitu.locate.part`; None: no frame) — which also
    place a part whose scan edges left it too uncertain, when they agree with its pose."""
    top = sols[0] if sols else None
    if top is None or top.fitness < s.min_fitness * 0.6 or top.coverage < s.min_coverage / 2:
        fit, cover = (top.fitness, top.coverage) if top else (0.0, 0.0)
        raise LocateRefused("no-part", f"part not found: at best the reference fits "
                                       f"{fit:.0%} of the {n:,} points above {where} and "
                                       f"covers {cover:.0%} of its top")
    if top.coverage < s.min_coverage:
        raise LocateRefused("partial", f"only partly in the scan: {top.coverage:.0%} of the "
                            f"reference's top measured (at least {s.min_coverage:.0%} needed) "
                            f"at {top.describe()}")
    near = [o for o in sols if o.score >= top.score - s.ambiguity]
    if prefer is not None:
        pick = [o for o in near if _in_range(o.angle_deg, *prefer)]
        if not pick:
            raise LocateRefused("not-preferred", "no well-fitting pose turned within "
                                f"{prefer[0]:g} … {prefer[1]:g}°: found "
                                + "; ".join(o.describe() for o in near))
        near = pick
    if len(near) > 1 and (why := slid(near[0], near[1])) is not None:
        raise LocateRefused("poor-fit", f"x, y and the turn are not pinned down: {why}",
                            near[0])
    if len(near) > 1:
        raise LocateRefused("ambiguous", f"ambiguous: {near[0].describe()} and "
                            f"{near[1].describe()} fit nearly equally (a symmetric part?): "
                            "say which with a preferred angle range LO HI")
    best = near[0]
    second = next((o for o in sols if o is not best), None)
    if best.fitness < s.min_fitness or best.rmse_mm > s.max_rmse_mm:
        raise LocateRefused("poor-fit", f"fits poorly: {best.describe()}, inlier RMSE "
                            f"{best.rmse_mm:.3f} mm (needed: fitness ≥ {s.min_fitness:.0%}, "
                            f"RMSE ≤ {s.max_rmse_mm:g} mm)")
    if framed is not None:
        best = framed(best)
    return best, second


def pinned(best: Solution, s: LocateSettings, advice) -> None:
    """LocateRefused unless ``best``'s 1σ at the rim puts it within the tolerance
    (:data:`SIGMAS` σ) and its scan and room-light frame do not disagree; ``advice()``: what
    would pin it down."""
    frame = f"; the room-light frame: {best.image_note}" if best.image_note else ""
    if best.image_conflict:
        raise LocateRefused("poor-fit", f"the scan's edges and the room-light frame's do not "
                            f"agree at {best.describe()}: {best.image_note}; scan it again "
                            "(did the part move?)", best)
    sigma = best.rim_sigma_mm
    if best.sigma_mm is None and not best.image_edges:
        raise LocateRefused("poor-fit", f"x, y and the turn are not pinned down at "
                            f"{best.describe()}: the cloud records no scan lines, so no edge "
                            f"gives them (the ICP alone: a few tenths of a mm){frame}; {advice()}",
                            best)
    if not np.isfinite(sigma):
        raise LocateRefused("poor-fit", f"x, y and the turn are not pinned down at "
                            f"{best.describe()}: {best.unheld}{frame}; {advice()}", best)
    turn, t = best.turn_sigma_deg, s.turn_tolerance_deg
    own = "" if t is None else f" and {t:g}°"
    if not margin(best, s) <= 1.0:
        by = (f"the room-light frame's edges ({best.image_edges} points)" if best.image_edges
              else f"the edges the scan lines cross ({best.edges} samples)")
        raise LocateRefused(
            "poor-fit", f"not pinned down to the tolerance at {best.describe()}: {by} hold it "
            f"to {sigma:.3f} mm at the part's rim and {turn:.3f}° (1σ; {SIGMAS:g}σ within "
            f"{s.tolerance_mm:g} mm{own}, 3σ of the turn within {s.turn_bound_deg:g}° "
            f"needed){frame}; {advice()}", best)
