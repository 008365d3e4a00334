"""The naive centre of mass the photograph tests compare the methods with
(benchmarks/real_lines.py's baseline, defined alike)."""

import numpy as np


def naive_com(channel: np.ndarray) -> np.ndarray:
    """(W,) row per column of an (H, W) channel: the centre of mass of the pixels within ±8 rows
    of the column's maximum that reach 0.8 of it."""
    g = channel.astype(np.float64)
    h, w = g.shape
    rows = np.clip(np.argmax(g, axis=0) + np.arange(-8, 9)[:, None], 0, h - 1)
    vals = g[rows, np.arange(w)]
    vals[vals < 0.8 * vals.max(axis=0)] = 0
    return (vals * rows).sum(axis=0) / vals.sum(axis=0)
