"""A tiny recorded sequence's setup (64 × 48 px) that the sequence tests share."""

import numpy as np

W, H = 64, 48
CAMERA = {"width": W, "height": H, "K": [[60.0, 0, 32.0], [0, 60.0, 24.0], [0, 0, 1]],
          "dist": [0.01, -0.02, 0.0, 0.0, 0.0], "R": np.eye(3), "t": [0.0, 0.0, 300.0]}
HEAD = {"lens": "non-telecentric", "pivot_height_mm": 350.0, "field_size_mm": [200.0, 200.0],
        "z_range_mm": [-25.0, 25.0]}


def line(x: float) -> dict:
    """A frame's commanded line along y at ``x`` mm, −40…40 mm."""
    return {"start": [x, -40.0], "end": [x, 40.0]}
