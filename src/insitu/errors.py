"""Every failure a user can cause or meet is an :class:`InsituError`.

The CLI prints ``str(error)`` as one line and exits non-zero; no traceback for these.
Messages name the file, the field and the expected value.
"""

import math


class InsituError(Exception):
    """Base of all user-facing failures. ``field``: the request field the message is about
    (``cut_path``); the message then starts with its name in words (``cut path 'x': expected
    one of …``), which the commands show as their option (``--cut-path 'x': …``)."""

    warnings: tuple[str, ...] = ()
    """Lines the operator should read with the error (what was found before the refusal)."""

    def __init__(self, *args, field: str | None = None):
        super().__init__(*args)
        self.field = field


class FormatError(InsituError):
    """A file is missing, unreadable or does not match its format (docs/formats.md)."""


class ConfigError(InsituError):
    """A rig or calibration file is invalid or does not fit the rig."""


class CalibrationError(InsituError):
    """A calibration cannot be computed from the data given."""


class MeasurementError(InsituError):
    """A measurement cannot be made (no line, heights not bracketed, empty result)."""


class DeviceError(InsituError):
    """A device failed, timed out or refused a command. The laser is off when this is raised."""


class SafetyError(InsituError):
    """A request would fire the laser where it must not (outside field or focus range).
    ``where_mm``: the place refused, world (x, y) mm, when the check knows one (else None)."""

    def __init__(self, message: str, where_mm: tuple[float, float] | None = None):
        super().__init__(message)
        xy = None if where_mm is None else (float(where_mm[0]), float(where_mm[1]))
        self.where_mm = xy if xy is not None and all(map(math.isfinite, xy)) else None
