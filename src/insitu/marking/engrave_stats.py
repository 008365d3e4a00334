"""The statistics of a pocket's floor points (:mod:`insitu.marking.engrave_depth`): each scan
line's shared error, the cells' weighted means and their standard errors, and the standard error
of the floor's mean depth.

A floor point's error goes with its neighbours' along the line: the speckle's grains (about
:data:`SPECKLE_MM` on the part: 2.44 λN/M ≈ 0.3 mm for a camera at f/8 seeing the part at 22×
demagnification, ``docs/simulator.md``) and the texture. The lines (each its own frame) are
independent, so the standard errors count lines, not points.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter
from scipy.spatial import cKDTree

SPECKLE_MM = 0.25
"""A line's speckle grains on the part (the 1/e length of their correlation along it), mm."""

SHARED_MM = 0.0012
"""A pocket's depth error that all of its floor lines share, so their scatter does not show it,
mm rms: on the simulated plate's 6 × 6 mm pockets the errors were 1.68 µm rms against a σ of
1.27 from the lines (and 1.48 against 0.81 on eight re-runs): ≈ 1.1–1.2 µm missing
(docs/accuracy.md, what the 6 mm σ misses). Its source is not pinned (the renderer's speckle
field, shared by all frames, is the suspect); a real rig's may differ: check it on a plate of
known depths."""


def line_sem(d: np.ndarray, line: np.ndarray, along_mm: np.ndarray, top_sem: float) -> float:
    """The standard error (mm) of the mean of ``d`` (N,) whose points share an error along
    their ``line`` (N,), at ``along_mm`` (N,) along it, with the top's own standard error
    ``top_sem`` mm beside it.

    The lines' scatter (the clustered estimate, L/(L−1) corrected) or, where larger, what
    the points' scatter along each line says a line's mean scatters by: a pocket's ~15 lines
    may all miss the speckle's rare strong grains, so their scatter can say half of what
    their mean scatters by (the simulated plate's seed 33, its 0.1 mm pocket: 1.7 µm; its
    depth over 12 speckle draws on the same plate scatters by 3.5 µm), while along the lines
    the grains show in ~3 blocks a line. :data:`SHARED_MM` beside both: what no line's
    scatter shows, which bounds a wide pocket's σ from below."""
    lines, inv = np.unique(line, return_inverse=True)
    if len(lines) < 2:
        return float("inf")
    sums = np.bincount(inv, d - d.mean())
    var = len(lines) / (len(lines) - 1) * (sums ** 2).sum() / len(d) ** 2
    return float(np.sqrt(max(var, _along_var(d, inv, along_mm)) + top_sem ** 2 + SHARED_MM ** 2))


def _along_var(d: np.ndarray, inv: np.ndarray, along_mm: np.ndarray) -> float:
    """The variance (mm²) of the mean of the lines' means (``inv`` (N,): each point's line,
    0 … L−1) their points' scatter along the lines gives: blocks of 2 × :data:`SPECKLE_MM`
    along each line (nearly independent) pooled about their line's mean, a line's mean the
    mean of its blocks."""
    block = np.floor((along_mm - along_mm.min()) / (2 * SPECKLE_MM)).astype(np.int64)
    key, binv = np.unique(inv.astype(np.int64) * (block.max() + 1) + block,
                          return_inverse=True)
    means = np.bincount(binv, d) / np.bincount(binv)
    of = key // (block.max() + 1)
    n = np.bincount(of).astype(float)
    dof = float((n - 1).sum())
    if dof < 1:
        return 0.0
    spread = ((means - (np.bincount(of, means) / n)[of]) ** 2).sum() / dof
    return float((spread / n).sum() / len(n) ** 2)


def line_terms(x, y, d, line, kernel_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """The floor's depths ``d`` (N,) with each scan line's own error removed, and the
    variance (mm²) of what is left of it per line (L,) (``line`` (N,): 0 … L−1): the lines'
    scatter in a cell does not show it (each was fitted to the lines around it).

    A line's floor points share an error the top's offset does not catch (the speckle and
    texture of the floor it crosses). Each point's residual against the other lines' points
    around it (Gaussian weights, σ ``kernel_mm``) averages, per line, to the line's term;
    the terms are shrunk by their evidence (a random effect: their spread beyond the
    residuals' noise) and centred, so the floor's mean depth is left as the lines give it."""
    n_lines = int(line.max()) + 1 if len(line) else 0
    if n_lines < 3:
        return d, np.zeros(n_lines)
    pts = np.column_stack([x, y])
    tree = cKDTree(pts)
    pairs = tree.query_pairs(3 * kernel_mm, output_type="ndarray")
    pairs = pairs[line[pairs[:, 0]] != line[pairs[:, 1]]]
    i, j = np.concatenate([pairs[:, 0], pairs[:, 1]]), np.concatenate([pairs[:, 1], pairs[:, 0]])
    w = np.exp(-((x[i] - x[j]) ** 2 + (y[i] - y[j]) ** 2) / (2 * kernel_mm ** 2))
    wsum = np.bincount(i, w, minlength=len(d))
    term, var = np.zeros(n_lines), np.zeros(n_lines)
    for _ in range(2):
        fixed = d - term[line]
        ref = np.bincount(i, w * fixed[j], minlength=len(d)) / np.maximum(wsum, 1e-12)
        ok = wsum > 1e-6
        r = d - ref
        n = np.bincount(line[ok], minlength=n_lines).astype(float)
        mean = np.bincount(line[ok], r[ok], minlength=n_lines) / np.maximum(n, 1)
        noise = (np.median(np.abs(r[ok] - mean[line[ok]])) * 1.4826) ** 2 / np.maximum(n, 1)
        has = n > 0
        between = max(float(np.var(mean[has]) - np.mean(noise[has])), 0.0) if has.any() else 0
        shrink = between / (between + noise)
        term = np.where(has, mean * shrink, 0.0)
        term -= np.average(term[has], weights=n[has]) if has.any() else 0.0
        var = np.where(has, noise * shrink, between)
    return d - term[line], var


def cell_means(cells, x, y, d, kernel_mm: float, line=None, line_var=None):
    """Per cell of ``cells`` (:class:`~insitu.marking.engrave_depth.PocketCells`) the
    Gaussian-weighted mean depth of the floor points, its standard error, and
    effective points; the robust point scatter; which points were kept (beyond 4σ of their
    cell's mean: left out, a ghost or a dropped centre).

    The standard error counts lines, not points: a floor point's error goes with its
    neighbours' along the line (the speckle's grains, the texture, what is left of the line's
    own error) and stays where it is scan after scan, while the lines (0.1 mm apart, each its
    own frame) are independent. A cell's depth is the weighted mean of its lines' means; the
    variance of a line's mean (pooled over the cells: their lines' weighted scatter about the
    cell's depth, the cell's own share taken out) times Σ (the line's weight share)², with
    what is left of the lines' own errors (``line_var`` (L,) mm², which the scatter does not
    show)."""
    shape = cells.shape
    if len(d) == 0:
        zero = np.zeros(shape)
        return zero, np.full(shape, np.inf), zero, float("nan"), np.zeros(0, bool)
    gx, gy = cells.centres()
    tree = cKDTree(np.column_stack([x, y]))
    keep = np.ones(len(d), bool)
    if line is None:
        line, line_var = np.zeros(len(d), int), np.zeros(1)
    for _ in range(2):
        depth, wsum, w2sum, share2, shared = (np.zeros(shape) for _ in range(5))
        scatter, dof = 0.0, 0.0
        near = tree.query_ball_point(np.column_stack([gx.ravel(), gy.ravel()]), 3 * kernel_mm)
        for k, idx in enumerate(near):
            idx = np.asarray(idx, int)
            idx = idx[keep[idx]]
            if len(idx) == 0:
                continue
            w = np.exp(-((x[idx] - gx.flat[k]) ** 2 + (y[idx] - gy.flat[k]) ** 2)
                       / (2 * kernel_mm ** 2))
            i, j = divmod(k, shape[1])
            depth[i, j] = (w * d[idx]).sum() / w.sum()
            wsum[i, j], w2sum[i, j] = w.sum(), (w * w).sum()
            lines, inv = np.unique(line[idx], return_inverse=True)
            wl = np.bincount(inv, w)
            ml = np.bincount(inv, w * d[idx]) / wl
            share = wl / w.sum()
            share2[i, j] = (share ** 2).sum()
            shared[i, j] = (share ** 2 * line_var[lines]).sum()
            scatter += (wl * (ml - depth[i, j]) ** 2).sum()
            dof += (wl * (1.0 - share)).sum()
        row, col = cells.index(x, y)
        resid = d - depth[row, col]
        sigma = float(np.median(np.abs(resid[keep])) * 1.4826)
        keep = np.abs(resid) <= 4 * max(sigma, 1e-6)
    neff = np.where(w2sum > 0, wsum ** 2 / np.where(w2sum > 0, w2sum, 1), 0.0)
    unit = scatter / dof if dof > 0 else sigma ** 2
    sem = np.where(neff > 0, np.sqrt(np.maximum(unit * share2, sigma ** 2 / np.maximum(
        neff, 1e-9)) + shared), np.inf)
    return depth, sem, neff, sigma, keep


def texture_var(depth: np.ndarray, ok: np.ndarray, cell_mm: float, kernel_mm: float) -> float:
    """The variance (mm²) a cell's depth (``depth`` (ny, nx) mm, the cells ``ok``) errs by
    from its cell's mean for the map's kernel: the kernel (σ ``kernel_mm``) averages the floor
    over more than the cell, so a floor with texture at that scale (a wood's rings, 1.5 mm
    apart: ≈ 4.5 µm rms, the same every scan) reads flattened. Its error is
    (σ²/2 − c²/24) ∇²(floor); the map smoothed once more by the kernel differs from the map
    by −σ²/2 ∇² of it, so (1 − c²/(12 σ²)) × that difference, squared and pooled over the
    cells, says the error's variance from the map itself (with a share of the cells' noise:
    on a flat floor ≈ 1.5 µm rms)."""
    if ok.sum() < 9:
        return 0.0
    w = gaussian_filter(ok.astype(float), kernel_mm / cell_mm)
    smooth = gaussian_filter(np.where(ok, depth, 0.0), kernel_mm / cell_mm)
    diff = (depth - smooth / np.maximum(w, 1e-9))[ok]
    return float(np.mean(diff ** 2)) * (1.0 - cell_mm ** 2 / (12.0 * kernel_mm ** 2)) ** 2


NOT_FLOOR_SIGMAS = 8.0
"""How far (robust σ of the pocket's floor points, or of the top's residuals where larger)
a floor point, or a line's median, may lie from the floor's median, and a point above the
top (the top's residual rms), before it cannot be floor."""


def floor_like(d: np.ndarray, line: np.ndarray, top_rms: float) -> np.ndarray:
    """(N,) bool: which of a pocket's points inside its outline can be its floor, from their
    depths ``d`` (N,) mm below the top and their scan ``line`` (N,): not above the top by more
    than its noise allows (``top_rms`` mm × :data:`NOT_FLOOR_SIGMAS` / 2), nor farther from the
    pocket's median depth than :data:`NOT_FLOOR_SIGMAS` × its robust spread, nor on a line
    whose median is. A light path the camera mistakes for the line (the simulated plate's
    0.5 mm pocket, walls sloping over 0.3 mm: one line 3 mm above the top) is one line's
    points far off; kept, its line's term spreads it over the map."""
    if len(d) == 0:
        return np.ones(0, bool)
    med = np.median(d)
    spread = max(1.4826 * np.median(np.abs(d - med)), top_rms, 1e-6)
    ok = (d >= -NOT_FLOOR_SIGMAS / 2 * top_rms) & (np.abs(d - med) <= NOT_FLOOR_SIGMAS * spread)
    lines, inv = np.unique(line, return_inverse=True)
    line_med = np.array([np.median(d[inv == k]) for k in range(len(lines))])
    return ok & (np.abs(line_med - med) <= NOT_FLOOR_SIGMAS * spread)[inv]
