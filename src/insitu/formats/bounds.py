"""Plausibility bounds: the one table of the ranges every number in a file or a command-line
option must lie in (inclusive), with the reason for each. A value outside is refused with one
line naming the field, the value and the range, e.g. ``job.json: laser.mark_speed_mm_s:
1e-300 is outside 0.1 … 20000 mm/s``.

The pydantic models use :func:`within` (one number) and :func:`each_within` (every number of a
list); plain dataclasses and the commands call :func:`check` / :meth:`Bound.problem`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any

from pydantic import AfterValidator

from insitu.errors import InsituError
from insitu.formats.validation import bad


@dataclass(frozen=True)
class Bound:
    """``lo`` ≤ value ≤ ``hi`` (finite), in ``unit``; ``why``: the reason for the range."""

    lo: float
    hi: float
    unit: str
    why: str

    def problem(self, value: Any) -> str | None:
        """None if ``value`` is a number within the range, else ``<value> is outside lo … hi
        unit``."""
        try:
            v = float(value)
        except OverflowError:                                   # an int beyond any float
            v = math.inf if value > 0 else -math.inf
        except (TypeError, ValueError):
            return f"{value!r} is not a number (expected {self.range_text()})"
        if math.isfinite(v) and self.lo <= v <= self.hi:
            return None
        shown = str(value) if isinstance(value, int) and abs(value) < 1e15 else f"{v:g}"
        return f"{shown} is outside {self.range_text()}"

    def range_text(self) -> str:
        return f"{_num(self.lo)} … {_num(self.hi)}" + (f" {self.unit}" if self.unit else "")


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e12 else f"{x:g}"


_SPEED = "galvo heads mark at 0.1 mm/s (slow deep engraving) up to 20 m/s"
_DELAY = "scan-head delays are tens to thousands of µs; 0.1 s is far beyond any head's"
_MM = "the largest scan fields are about 1.5 m; no point of a station lies beyond 1 m"
BOUNDS: dict[str, Bound] = {
    # -- laser (job files, --power/--frequency/--speed/--jump-speed, line projection) --
    "power_pct": Bound(0, 100, "%", "percent of full power"),
    "frequency_khz": Bound(1, 4000, "kHz", "Q-switched and MOPA fibre, CO2 and UV sources "
                           "pulse from 1 kHz to 4 MHz"),
    "mark_speed_mm_s": Bound(0.1, 20000, "mm/s", _SPEED),
    "jump_speed_mm_s": Bound(1, 50000, "mm/s", "galvo jumps reach 50 m/s on the fastest heads"),
    "delay_us": Bound(0, 100000, "µs", _DELAY),
    "corner_deg": Bound(0, 180, "°", "a turn angle"),
    "passes": Bound(1, 100, "", "a pen marks each path 1 … 100 times (deep engraving)"),
    "depth_mm": Bound(0.001, 20, "mm", "an engraving's depth: 1 µm … a deep mould cavity"),
    "rescan_every": Bound(1, 1000, "passes", "an engraving measures after 1 … 1000 passes"),
    "laser_power_w": Bound(0.01, 20000, "W", "marking sources: 10 mW diodes … 20 kW fibre"),
    "spot_um": Bound(1, 5000, "µm", "a focused spot: 1 µm … 5 mm"),
    "threshold_j_cm2": Bound(0.001, 1000, "J/cm²", "ablation thresholds: 0.01 J/cm² "
                             "(polymers, fs) … tens of J/cm² (ceramics, long pulses)"),
    "penetration_um": Bound(0.001, 1000, "µm", "effective penetration depths: 10 nm "
                            "(metals, fs) … hundreds of µm (wood, CO2)"),
    "wobble_amplitude_mm": Bound(0.001, 5, "mm", "a wobble widens a line by up to a few mm "
                                 "(welding, bold marks)"),
    "wobble_hz": Bound(1, 50000, "Hz", "galvos follow a wobble circle up to a few kHz; 50 kHz "
                       "is beyond any"),
    "wobble_pitch_mm": Bound(0.001, 10, "mm", "path length per wobble turn"),
    "sweeps": Bound(1, 1000, "", "back-and-forth passes of a projected line per list"),
    # -- camera (sequence.json, camera.json, height calibrations) --
    "image_px": Bound(1, 100000, "px", "image width/height: sensors are below 100k px a side"),
    "focal_px": Bound(10, 1e6, "px", "fx, fy: a 1 µm pixel behind a 1 m lens is 1e6 px"),
    "dist_k1": Bound(-10, 10, "", "k1 of a real lens is within ±1; ±10 bends the image edge "
                     "by more than the image (a fit gone wrong)"),
    "dist_tangential": Bound(-1, 1, "", "p1, p2: decentring of a lens is ≪ 1"),
    "dist_other": Bound(-1000, 1000, "", "k2…k6, s1…s4, tilt: the rational model's terms "
                        "cancel one another and can be large, but not beyond ±1000"),
    "camera_t_mm": Bound(-10000, 10000, "mm", "the camera is within 10 m of the field"),
    # -- scan head (scan_head of a sequence, scan-head.json, height calibrations) --
    "pivot_height_mm": Bound(1, 2000, "mm", "f-theta working distances are 50 … 1500 mm"),
    "field_size_mm": Bound(1, 2000, "mm", _MM),
    "position_mm": Bound(-1000, 1000, "mm", _MM),
    "mirror_distance_mm": Bound(1, 2000, "mm", "the second mirror is above the field by about "
                                "the working distance"),
    "mirror_separation_mm": Bound(0, 200, "mm", "the two galvo mirrors are 5 … 50 mm apart"),
    # -- scan-head boards (rig file options.lmc / options.rtc) --
    "bits_per_deg": Bound(10, 100000, "bits/°", "LMC: 16-bit galvo commands over a ±10 … "
                          "±30° mechanical range are about 1000 … 3300 bits/°"),
    "k_bits_per_mm": Bound(1, 1000000, "bits/mm", "RTC: the 20-bit range over a field of "
                           "1 mm … 1 m"),
    "focus_tolerance_mm": Bound(0, 100, "mm", "an LMC head has no dynamic focus: the depth of "
                                "field is a few mm"),
    "timeout_s": Bound(0.01, 3600, "s", "no list or move takes an hour"),
    "heartbeat_s": Bound(0.001, 60, "s", "the watchdog's ping interval"),
    "feed_mm_min": Bound(1, 100000, "mm/min", "a Z stage moves at 1 mm/min … 1.7 m/s"),
    "exposure_ms": Bound(0.001, 10000, "ms", "a camera exposure: 1 µs … 10 s"),
    "ambient_grey": Bound(0, 1, "of full scale", "a cloud's ambient: the room-light grey value "
                          "of a pixel, black 0 … full scale 1"),
    "gain_db": Bound(-20, 60, "dB", "industrial camera gains span about 0 … 48 dB"),
    "usb_timeout_ms": Bound(1, 60000, "ms", "a USB transfer"),
    "pulse_length_us": Bound(0, 10000, "µs", "a laser pulse or its trigger"),
    "board_index": Bound(0, 64, "", "boards, cards, pins and tables are numbered from 0 or 1 "
                         "to a few dozen"),
    # -- height calibration (sheet and paper models) --
    "exponent": Bound(0, 12, "", "polynomial degrees: the fit uses up to 6; a negative "
                      "exponent divides by zero at x = 0"),
    "coefficient_mm": Bound(-1e4, 1e4, "mm", "a correction term of a normalised polynomial; "
                            "the sheets are within a few mm of the nominal planes"),
    "scale_mm": Bound(1e-3, 1e4, "mm", "the polynomial's normalisation lengths"),
    "pixel_px": Bound(-1e6, 1e6, "px", "a pixel coordinate or a fitted image quantity"),
    "line_angle_deg": Bound(0, 180, "°", "a line's direction from +x; a half turn is the "
                            "same line"),
    # -- field correction --
    "rbf_sigma_mm": Bound(1e-3, 1e4, "mm", "the RBF spread is a fraction of the field"),
    "mse_goal_mm2": Bound(0, 100, "mm²", "the RBF fit's goal: errors are well below 10 mm"),
    "rbf_weight_mm": Bound(-1e6, 1e6, "mm", "RBF weights of close neurons oppose one another "
                           "(an OLS fit on 21 × 21 marked circles: up to 12,000)"),
    "correction_mm": Bound(-100, 100, "mm", "a landing error of a scan head is below 100 mm"),
    "smoothing": Bound(0, 1e6, "", "a spline's smoothing factor"),
    "tolerance_mm": Bound(1e-6, 100, "mm", "a landing-error tolerance"),
    "turn_bound_deg": Bound(1e-6, 90, "°", "how far a located turn may be off"),
    # -- command-line options --
    "binning": Bound(1, 16, "", "the simulated camera is 2448×2048 px: 16 leaves 153×128"),
    "spacing_mm": Bound(0.001, 100, "mm", "scan line spacing: 1 µm … 100 mm"),
    "angle_deg": Bound(-3600, 3600, "°", "a rotation or direction: ten turns either way"),
    "seed": Bound(0, 2**32 - 1, "", "numpy's seeds are 0 … 2³²-1"),
    "length_mm": Bound(0.001, 2000, "mm", "a width, hatch distance or beam: 1 µm … the field"),
    "count": Bound(1, 1000, "", "views or spots per side of a recording"),
    "parts": Bound(1, 1000000, "", "parts of one production run: a shift marks thousands"),
    "board_corners": Bound(2, 200, "", "inner corners of a checkerboard along a side"),
    "move_mm": Bound(-1000, 1000, "mm", "a simulated knock of the camera"),
    # -- locating a part (POSE.json, insitu locate) --
    "fraction": Bound(0, 1, "", "a share of points: 0 … 1"),
    "residual_mm": Bound(0, 100, "mm", "a fit's RMSE: a part located within 100 mm of its "
                         "surface has not been located"),
    "duration_s": Bound(0, 86400, "s", "a step of a station's work takes less than a day"),
    "point_count": Bound(0, 1e9, "", "a cloud of the largest fields at 10 µm is 1e9 points"),
}


def check(name: str, value: Any, field: str, error: type[InsituError] = InsituError) -> Any:
    """``value`` if within ``BOUNDS[name]``, else ``error`` ``field: <value> is outside …``."""
    why = BOUNDS[name].problem(value)
    if why is not None:
        raise error(f"{field}: {why}")
    return value


def check_fields(obj: Any, names: dict[str, str], prefix: str,
                 error: type[InsituError] = InsituError) -> None:
    """Check each attribute of ``obj`` named in ``names`` (attribute → bound; None passes):
    ``error`` ``<prefix>.<attribute>: <value> is outside …`` for the first out of range."""
    for attr, bound in names.items():
        value = getattr(obj, attr)
        if value is not None:
            check(bound, value, f"{prefix}.{attr}", error)


def within(name: str, kind: type = float) -> Any:
    """An ``Annotated`` number type (``kind`` float or int) checked against ``BOUNDS[name]``."""
    b = BOUNDS[name]

    def validate(v: Any) -> Any:
        why = b.problem(v)
        if why is not None:
            raise bad(why)
        return v
    return Annotated[kind, AfterValidator(validate)]


def each_within(name: str) -> AfterValidator:
    """A validator for a list (or a list of lists) of numbers: each within ``BOUNDS[name]``;
    the error names the item, e.g. ``exponents[3][1]``."""
    b = BOUNDS[name]

    def validate(v: Any) -> Any:
        for i, x in enumerate(v):
            for j, y in (enumerate(x) if isinstance(x, (list, tuple)) else [(None, x)]):
                why = b.problem(y)
                if why is not None:
                    raise bad(why, at=f"[{i}]" + ("" if j is None else f"[{j}]"))
        return v
    return AfterValidator(validate)
