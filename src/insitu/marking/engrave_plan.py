"""An engraving's rounds, planned per cell of the pocket from what its measurements say.

The model: a cell's depth grows by its own rate with every pass (depth = rate × passes; a
wood's rings, the anodic layer's thickness and the walls' taper make the rate differ from cell
to cell). Every measurement of a cell (its depth m at P passes, standard error s) adds to the
least-squares fit of its rate through the origin (s² with the error a scan shares over the
pocket, :data:`SCAN_ERROR_MM`, so that a later measurement, at more passes, weighs more); the
cells' rates are pulled towards the pocket's rate by how much of their spread the
measurements' noise explains (a random effect: τ², the rates' true spread, is what their
spread has beyond the noise). So a noisy
measurement moves a cell's estimate only by what it is worth, and passes never chase noise.

Only a measured cell's depth (:data:`~insitu.marking.engrave_depth.MEASURED`: enough floor
points beyond the walls' bias zone at its depth) is learnt from: a cell the measurement cannot
vouch for (the wall band, too few trusted points, the bias zone of a wall close for the depth)
follows the model: never more passes than reach the depth at the mean rate of the measured
cells within one cell around it plus :data:`UNTRUSTED_SIGMAS` σ (how far a measured cell's
rate strays from its neighbours' mean; :func:`_untrusted_rate`). Until the
first such measurement, a round stops where the deepest-trusted cell would leave its zone (at
:data:`RATE_MARGIN` × the rate), so that a narrow pocket is measured while its floor can be.

Each round's passes: the depth still missing over the cell's rate, at most ``rescan_every``; before
a measurement, :data:`APPROACH` of what the table's rate says. Once the rate is learnt, the joined
estimate: the passes that reach the target at the cell's rate plus :data:`AIM_SIGMAS` σ of it (short
of the target by that many σ of what the passes to go add: their count times the rate's σ, the
extrapolation's error, large while the floor is far, small near it; a rate known poorly gives short
steps, never none), as whole passes of the pen and the fraction left as finishing passes
(:func:`finishing_pen`: the pen faster, each pass a fraction of one), so a round ends within a
finishing pass of where it aims. A round whose measured cells asking for passes are fewer than
:data:`FEW_CELLS` of them is not worth its marking and scan: they are left (a trickle of rounds,
each re-measuring the pocket for a few cells' noise, gains nothing the 95 % band shows). A cell at
its depth gets no more energy, and the stop rule speaks for the measurement's uncertainty: a
measured cell gets more passes only while the depth it misses exceeds :data:`STOP_SIGMAS` σ of its
measured depth (the last map's standard error, with the estimate's), and never more than reach the
depth plus one pass at the slowest rate the pocket's cells likely have (what the model predicts
bounds what one measurement can ask for: an error the scans repeat cannot pull a cell down). A cell
the camera cannot see (a wall hides it) gets passes only while its passes at its highest likely rate
(:data:`RATE_MARGIN` × its rate, or its rate plus three times the σ of the cells' spread and of the
rate's estimate, whichever is higher) stay short of the target: it is never over-burnt, and is
reported when that leaves it short.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt, maximum_filter, uniform_filter

from insitu.formats.materials import LaserSource, Material
from insitu.formats.pens import Pen
from insitu.marking.engrave_depth import (
    HIDDEN,
    MEASURED,
    OUTSIDE,
    DepthMap,
    PocketCells,
)

APPROACH = 0.9          # before the rate is learnt: this fraction of the passes the table says
AIM_SIGMAS = 3.0        # once learnt: the rest short of the target by this many σ of its error
FEW_CELLS = 0.02        # fewer measured cells than this share short: not worth a round and a scan
FINISH_SPEED = 2.0      # a finishing pass: the pen this many times faster (fewer pulses per area)
RATE_MARGIN = 1.15      # a cell not seen is planned as if it ablated this much faster
UNTRUSTED_SIGMAS = 2.0  # a cell not measured is planned at its rate + this many σ of its rate
NEAR_CELLS = 2          # the cells around (this many) whose rates say how far a rate strays
MIN_PAIRS = 6           # ... when this many of them have measured neighbours (else the pocket's)
STOP_SIGMAS = 1.0       # a measured cell gets more passes only when this many σ short
SCAN_ERROR_MM = 0.004   # a depth scan's error shared by the pocket's cells (the floor's speckle
                        # changes pass to pass; benchmarks/engrave.py measure: 1 … 7 µm)
_FIELDS = ("passes", "spp", "sp2", "rate", "rate_var", "estimate")


@dataclass
class CellHistory:
    """Per cell (ny, nx): ``passes`` given so far (fractional where a round was cut short);
    ``spp`` Σ P·m/s² and ``sp2`` Σ P²/s² over its measurements (depth m mm at P passes,
    standard error s mm); ``rate`` (mm per pass) and its variance ``rate_var``;
    ``estimate`` the depth it is believed at now (mm)."""

    passes: np.ndarray
    spp: np.ndarray
    sp2: np.ndarray
    rate: np.ndarray
    rate_var: np.ndarray
    estimate: np.ndarray

    @classmethod
    def start(cls, shape, rate_mm: float) -> "CellHistory":
        z = np.zeros(shape)
        return cls(z.copy(), z.copy(), z.copy(), np.full(shape, rate_mm),
                   np.full(shape, (0.3 * rate_mm) ** 2), z.copy())

    def to_dict(self) -> dict:
        return {k: getattr(self, k).tolist() for k in _FIELDS}

    @classmethod
    def from_dict(cls, d: dict) -> "CellHistory":
        return cls(*(np.asarray(d[k], float) for k in _FIELDS))

    def given(self, passes: np.ndarray) -> None:
        """``passes`` (ny, nx) more marked: the estimates move on at the cells' rates."""
        self.passes = self.passes + passes
        self.estimate = self.rate * self.passes


@dataclass(frozen=True)
class Learnt:
    """What the measurements so far teach: the pocket's ``rate_mm`` per pass, its standard
    error, the spread of the cells' rates (``spread_mm``, their σ beyond the noise) and the
    ``cells`` it came from."""

    rate_mm: float
    rate_sem_mm: float
    spread_mm: float
    cells: int


def owners(cells: PocketCells) -> tuple[np.ndarray, np.ndarray]:
    """(ny, nx) row and column of the pocket cell each cell belongs to: itself inside the
    pocket, else its nearest inside cell (an edge cell whose centre lies outside)."""
    _, (r, c) = distance_transform_edt(~cells.inside, return_indices=True)
    return r, c


def learn(history: CellHistory, dm: DepthMap, nominal_rate_mm: float) -> Learnt:
    """Add the measurement ``dm`` to ``history`` and fit the rates again (see the module
    docstring); the nominal rate stands until a measured cell has passes."""
    seen = ((dm.state == MEASURED) & np.isfinite(dm.depth)
            & np.isfinite(dm.sem) & (history.passes > 0))
    s2 = np.where(seen, np.maximum(dm.sem, 1e-4) ** 2 + SCAN_ERROR_MM ** 2, np.inf)
    history.spp = history.spp + np.where(seen, history.passes * np.nan_to_num(dm.depth) / s2, 0)
    history.sp2 = history.sp2 + np.where(seen, history.passes ** 2 / s2, 0)
    fit = (history.sp2 > 0) & (dm.state == MEASURED)
    if fit.sum() < 3:
        return Learnt(nominal_rate_mm, float("nan"), float("nan"), 0)
    raw = history.spp[fit] / history.sp2[fit]
    noise = 1.0 / history.sp2[fit]
    rate = float(np.average(raw, weights=1 / noise))
    tau2 = max(float(np.var(raw) - np.mean(noise)), 0.0)
    # the scan's shared error does not average over the cells: at least its share of the
    # deepest measurement bounds the pocket rate's error
    shared = SCAN_ERROR_MM / max(float(history.passes[fit].max()), 1.0)
    rate_sem2 = float(np.var(raw) / fit.sum()) + shared ** 2
    has = history.sp2 > 0
    prior = 1.0 / max(tau2, 1e-12)
    post = np.where(has, (history.spp + rate * prior) / (history.sp2 + prior), rate)
    history.rate = post
    history.rate_var = np.where(has, 1.0 / (history.sp2 + prior), tau2) + rate_sem2
    history.estimate = history.rate * history.passes
    return Learnt(rate, float(np.sqrt(rate_sem2)), float(np.sqrt(tau2)), int(fit.sum()))


def _stopped(history: CellHistory, need: np.ndarray, rate: np.ndarray, target_mm: float,
             sigma_mm: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """The passes the measured cells still need once the stop rule has spoken: none where the
    depth missing is within :data:`STOP_SIGMAS` σ of the cell's depth (its last measurement's
    standard error and its estimate's), and never more than reach the depth plus one pass at
    the slowest rate the pocket's cells likely have (its median less two σ of their
    spread): what the model predicts bounds what a measurement can ask for."""
    sigma = np.hypot(np.nan_to_num(sigma_mm, nan=np.inf, posinf=np.inf),
                     history.passes * np.sqrt(history.rate_var))
    missing = need * rate
    need = np.where(missing > STOP_SIGMAS * sigma, need, np.minimum(need, 0.0))
    pocket = float(np.median(rate[measured]))
    slow = max(pocket - 2.0 * float(np.std(rate[measured])), 0.5 * pocket)
    most = np.floor((target_mm + pocket) / slow) - history.passes
    return np.minimum(need, most)


def _untrusted_rate(history: CellHistory, rate: np.ndarray, inside: np.ndarray,
                    measured: np.ndarray) -> np.ndarray:
    """(ny, nx) the rate a cell the measurement cannot vouch for is planned at: the mean rate
    of the measured cells within one cell around it plus :data:`UNTRUSTED_SIGMAS` σ, σ how far
    a measured cell's rate lies from the mean of its measured neighbours' (left out of it,
    rms over the measured cells within :data:`NEAR_CELLS`, over the pocket where fewer than
    :data:`MIN_PAIRS` are) with the error the pocket's rates share (the least of their σ);
    never below its own rate + that many σ once it was measured. Where no measured cell is
    within one (or no measured cell has a measured neighbour): the highest of its own and
    the measured cells' within :data:`NEAR_CELLS`, each plus that many σ of it; with none
    around, the higher of its rate and the pocket's median plus that many σ of it."""
    sd = np.sqrt(history.rate_var)
    up = rate + UNTRUSTED_SIGMAS * sd
    pocket = float(np.median(rate[inside])) if inside.any() else 0.0
    alone = np.maximum(rate, pocket) + UNTRUSTED_SIGMAS * sd
    near = maximum_filter(np.where(measured, up, -np.inf), size=2 * NEAR_CELLS + 1,
                          mode="constant", cval=-np.inf)
    own = np.where(history.sp2 > 0, up, -np.inf)
    out = np.where(np.isfinite(near), np.maximum(near, own), alone)
    n = np.rint(uniform_filter(measured.astype(float), 3, mode="constant") * 9)
    total = uniform_filter(np.where(measured, rate, 0.0), 3, mode="constant") * 9
    pair = measured & (n >= 2)
    if pair.sum() < 3:
        return out
    r2 = np.where(pair, (rate - (total - rate) / np.maximum(n - 1, 1)) ** 2, 0.0)
    size = 2 * NEAR_CELLS + 1
    pairs = np.rint(uniform_filter(pair.astype(float), size, mode="constant") * size ** 2)
    local = uniform_filter(r2, size, mode="constant") * size ** 2 / np.maximum(pairs, 1)
    var = np.where(pairs >= MIN_PAIRS, local, r2[pair].mean())
    sigma = np.sqrt(var + sd[measured].min() ** 2)
    mean = total / np.maximum(n, 1) + UNTRUSTED_SIGMAS * sigma
    return np.where(n > 0, np.maximum(mean, own), out)


def finishing_pen(material: Material, laser: LaserSource) -> tuple[Pen, float]:
    """The pen of the finishing passes and their speed over the material's pen's: its pen
    moved :data:`FINISH_SPEED` times faster (the same pulses, so each pass removes that many
    times less: exactly, whatever the true threshold, as the pulses per area set the rate),
    slower where the pulses would no longer overlap along the line (their pitch beyond the
    spot's diameter). Speed 1: no finishing passes."""
    pen = material.pen
    pitch_mm = pen.mark_speed_mm_s / (pen.frequency_khz * 1e3)
    speed = max(min(FINISH_SPEED, laser.spot_um * 1e-3 / pitch_mm), 1.0)
    return pen.model_copy(update={"name": f"{pen.name}-finish",
                                  "mark_speed_mm_s": pen.mark_speed_mm_s * speed}), speed


@dataclass(frozen=True)
class RoundPlan:
    """The passes (ny, nx) int each cell gets in the next round with the material's pen,
    then ``finish`` (ny, nx) int with the finishing pen (each :data:`FINISH_SPEED` times
    fewer pulses per area: that share of a pass); ``held``: cells short of the target that
    get no more (the camera does not see them and their allowance is spent)."""

    passes: np.ndarray
    finish: np.ndarray
    held: np.ndarray

    @property
    def layers(self) -> int:
        """The round's layers: the pen's, then the finishing pen's."""
        if not self.passes.size:
            return 0
        return int(self.passes.max()) + int(self.finish.max())

    @property
    def finishing(self) -> bool:
        return bool(self.finish.any())

    def equivalent(self, speed: float = FINISH_SPEED) -> np.ndarray:
        """(ny, nx) the round's passes counted in the pen's passes."""
        return self.passes + self.finish / speed


def split(total: np.ndarray, cap: np.ndarray, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """``total`` (ny, nx) passes (fractional, in the pen's) as whole passes of the pen and
    finishing passes (1 / ``speed`` of one each, the rest rounded), never beyond ``cap``."""
    total = np.maximum(np.minimum(total, cap), 0.0)
    whole = np.floor(total + 1e-9)
    fine = np.round((total - whole) * speed)
    fine = np.where(whole + fine / speed > cap + 1e-9, np.floor((cap - whole) * speed + 1e-9),
                    fine)
    carry = fine >= speed
    return np.where(carry, whole + 1, whole), np.where(carry, 0.0, np.maximum(fine, 0.0))


def plan_round(history: CellHistory, state: np.ndarray, target_mm: float,
               rescan_every: int, trusted_to_mm: np.ndarray | None = None,
               sigma_mm: np.ndarray | None = None, speed: float = FINISH_SPEED) -> RoundPlan:
    """The next round's passes per cell (``state``: the last depth map's cell states; all
    measured before the first measurement). ``trusted_to_mm`` (ny, nx): the depth down to
    which each cell's measurement is trusted (None: any); ``sigma_mm`` (ny, nx): the last
    measurement's standard error per cell (None: not measured yet); ``speed``: a finishing
    pass's speed over the pen's (1: no finishing passes)."""
    inside = state != OUTSIDE
    rate = np.maximum(history.rate, 1e-6)
    need = np.where(inside, (target_mm - history.estimate) / rate, 0.0)
    measured = inside & (state == MEASURED)
    if sigma_mm is not None and measured.any():
        need = np.where(measured, _stopped(history, need, rate, target_mm, sigma_mm, measured),
                        need)
    learnt = bool((history.sp2 > 0).any())
    if learnt:
        # the joined estimate: the rest at the cell's rate plus AIM_SIGMAS σ of it, so that
        # the passes to go stay short of the target unless the rate is that much higher
        go = need * rate / (rate + AIM_SIGMAS * np.sqrt(history.rate_var))
    else:
        go = np.floor(APPROACH * need)
    cap = np.full(need.shape, float(rescan_every))
    blind = inside & (state == HIDDEN)
    rate_hi = np.maximum(RATE_MARGIN * rate, rate + 3.0 * np.sqrt(history.rate_var))
    cap = np.where(blind, np.minimum(cap, target_mm / rate_hi - history.passes), cap)
    untrusted = inside & ~measured & ~blind
    allowance = target_mm / _untrusted_rate(history, rate, inside, measured) - history.passes
    cap = np.where(untrusted, np.minimum(cap, allowance), cap)
    if learnt:
        go = np.where(untrusted, allowance, go)     # no measurement will say it is short
    if trusted_to_mm is not None and not learnt and inside.any():
        reach = float(trusted_to_mm[inside].max())
        fastest = RATE_MARGIN * float(rate[inside].max())
        if reach < target_mm and reach >= fastest:
            cap = np.minimum(cap, int(reach / fastest))
    passes, finish = split(np.where(inside, go, 0.0), np.where(inside, cap, 0.0),
                           speed if learnt and speed > 1 else 1.0)
    if not (learnt and speed > 1):
        finish = np.zeros_like(passes)
    if learnt and sigma_mm is not None and measured.any():
        asks = measured & ((passes > 0) | (finish > 0))
        if asks.sum() < FEW_CELLS * measured.sum():
            passes, finish = np.where(measured, 0.0, passes), np.where(measured, 0.0, finish)
    held = blind & (need >= 0.5) & (passes == 0) & (finish == 0)
    return RoundPlan(passes.astype(int), finish.astype(int), held)
