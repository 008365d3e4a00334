"""Use cases shared by the CLI, the GUI and the tests: they take progress callbacks and a
cancel event, touch devices and files, and return plain results."""

from insitu.services.common import Progress, camera_model
from insitu.services.height import (
                                    calibrate_height,
                                    centre_settings,
                                    height_model,
                                    load_height_calibration,
)
from insitu.services.scan import (
                                    Cancelled,
                                    ScanFrame,
                                    ScanResult,
                                    ScanSummary,
                                    save_cloud,
                                    scan_live,
                                    scan_replay,
)
from insitu.services.scan_frames import ScanInterrupted

__all__ = ["Cancelled", "Progress", "ScanFrame", "ScanInterrupted", "ScanResult", "ScanSummary",
           "calibrate_height", "camera_model", "centre_settings", "height_model",
           "load_height_calibration", "save_cloud", "scan_live", "scan_replay"]
