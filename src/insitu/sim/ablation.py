"""Material removed by the marking laser in the simulated world: the ablation law per pulse,
summed over a burn's pulses on a grid over the part's top (:class:`Engraving`), and the part's
surface with its pockets for the ray casting (:func:`engraved_part`).

The law. A pulse of energy E in a Gaussian spot of 1/e² radius w has the peak fluence
F0 = 2E / (π w²); a surface point at r from the spot's centre whose normal is turned by θ from
the beam loses

    d = δ · ln(F0 · exp(−2 r² / w²) · cos θ / F_th)      where that is > 0,

the logarithmic ablation law (δ = 1/α, the effective penetration depth; Nolte et al., J. Opt.
Soc. Am. B 14 (1997) 2716), whose volume per pulse on a flat surface is
V = π w² δ ln²(F0 / F_th) / 4 (Neuenschwander et al., Proc. SPIE 8243 (2012) 824307). The spot
grows with the defocus (w = w0 √(1 + (Δz / z_R)²)), so a focus that does not follow the floor
removes less; a wall turned from the beam takes less fluence, so walls come out tapered.

A burn (one pass along a path) is a line of samples, each carrying the pulses fired while the
spot crossed it (frequency × time): its pulse counts are spread onto the grid and convolved
with the crater of one pulse (a few classes of cos θ, interpolated per cell). Run to run and
over the part the rate is not the nominal one: each blank's δ is off by a factor drawn once
(``rate_spread``, ±10 %), varies over the part (``grain``: a wood's growth rings, an anodic
layer's thickness) and from pulse to pulse (``roughness``: a rougher floor pass after pass).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

from insitu.errors import ConfigError
from insitu.sim import meshes
from insitu.sim.workpieces import Workpiece, to_part, to_world

CELL_MM = 0.01            # the removal grid's cell: 2.5 cells per 1/e² radius of the spot
MESH_STEP = 2             # the ray-cast surface takes every 2nd node (0.02 mm)
MAX_CELLS = 4000          # per side: a 40 mm engraving at most
_COS_CLASSES = np.array([1.0, 0.85, 0.7, 0.55, 0.4, 0.25, 0.1])


@dataclass(frozen=True)
class AblationMaterial:
    """True ablation constants of a material for a ns-pulsed 1064 nm fibre laser:
    ``threshold_j_cm2`` F_th, ``penetration_um`` δ = 1/α; ``rate_spread``: a blank's δ lies
    within ±this of the nominal (drawn once per blank); ``grain``: relative amplitude of the
    rate's variation over the part, ``grain_mm`` its period, ``grain_deg`` the direction its
    bands run (a wood's rings; 0: isotropic blotches); ``roughness``: coefficient of variation
    of one pass's removal, correlated over the spot; ``max_depth_mm``: what can be removed
    before the blank is through."""

    threshold_j_cm2: float
    penetration_um: float
    rate_spread: float = 0.10
    grain: float = 0.0
    grain_mm: float = 1.0
    grain_deg: float | None = None
    roughness: float = 0.25
    max_depth_mm: float = 4.0


# The simulated world's truth (the operator's table, formats/materials.py, holds its own
# handbook values; the loop must learn the difference). Effective constants of ns Yb-fibre
# ablation, within the ranges reported for:
#  - stainless steel 304/316L: thresholds of 1–5 J/cm² for ns pulses (Radmanesh & Kiani,
#    Mater. Sci. Appl. 6 (2015) 521), removal rates of a 20 W source of a few mm³/min
#    (Hribar et al., Nanomaterials 12 (2022) 232); homogeneous.
#  - anodised aluminium 6061 (20 µm anodic layer): lower threshold and larger effective depth
#    (ns ablation of Al 6061: Terragni et al., arXiv:2108.11665 (2021)); the layer's
#    thickness varies by a few per cent.
#  - beech (a hardwood): threshold well under 1 J/cm² at 1064 nm and a depth per pulse of
#    micrometres (Panzner et al., Appl. Surf. Sci. 127–129 (1998) 787); early and late wood
#    of its rings ablate differently (±12 %, bands ~1.5 mm apart).
ABLATION: dict[str, AblationMaterial] = {
    "blank-stainless": AblationMaterial(2.1, 0.42, grain=0.02, grain_mm=3.0, roughness=0.2),
    "blank-anodised": AblationMaterial(1.3, 0.62, grain=0.05, grain_mm=2.0, roughness=0.25),
    "blank-beech": AblationMaterial(0.55, 1.9, grain=0.12, grain_mm=1.5, grain_deg=20.0,
                                    roughness=0.25),
}


@dataclass(frozen=True)
class MarkingBeam:
    """The true marking laser: ``power_w`` average power at 100 %, ``waist_mm`` the 1/e²
    radius at focus, ``rayleigh_mm`` z_R of the M² beam (1064 nm)."""

    power_w: float = 19.0
    waist_mm: float = 0.026
    rayleigh_mm: float = 1.55

    def radius_mm(self, defocus_mm: np.ndarray) -> np.ndarray:
        return self.waist_mm * np.sqrt(1.0 + (np.asarray(defocus_mm) / self.rayleigh_mm) ** 2)


@dataclass(eq=False)
class Engraving:
    """The material removed from one part's top: ``removed`` (ny, nx) float32 mm on a grid in
    the part's own frame, node (0, 0) at ``origin`` (x, y) mm, :data:`CELL_MM` apart; ``top``
    (ny, nx) the part's top there before any removal; ``rate`` (ny, nx) this blank's δ
    factor there (its spread and grain); ``version`` counts the burns applied."""

    material: AblationMaterial
    seed: int
    origin: np.ndarray = field(default_factory=lambda: np.zeros(2))
    removed: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), np.float32))
    top: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    rate: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    version: int = 0

    def nodes(self, i0=0, i1=None, j0=0, j1=None) -> tuple[np.ndarray, np.ndarray]:
        """Part-frame x (nx,) and y (ny,) of the grid's nodes (a sub-range)."""
        ny, nx = self.removed.shape
        xs = self.origin[0] + CELL_MM * np.arange(nx)[j0:j1]
        ys = self.origin[1] + CELL_MM * np.arange(ny)[i0:i1]
        return xs, ys

    def cover(self, part: Workpiece, lo: np.ndarray, hi: np.ndarray) -> None:
        """Grow the grid over the part-frame box ``lo``–``hi`` (2,) mm (plus the crater's
        reach), keeping what was removed."""
        lo, hi = np.asarray(lo, float) - 0.1, np.asarray(hi, float) + 0.1
        ny, nx = self.removed.shape
        if nx:
            old_hi = self.origin + CELL_MM * np.array([nx - 1, ny - 1])
            if np.all(lo >= self.origin - 1e-9) and np.all(hi <= old_hi + 1e-9):
                return
            lo, hi = np.minimum(lo, self.origin), np.maximum(hi, old_hi)
        # grown by 2 mm beyond what is asked: a hatch does not regrow it line by line
        lo = np.floor((lo - 2.0 * (lo < self.origin if nx else 1)) / CELL_MM) * CELL_MM
        hi = np.ceil((hi + 2.0 * (hi > old_hi if nx else 1)) / CELL_MM) * CELL_MM
        size = np.round((hi - lo) / CELL_MM).astype(int) + 1
        if size.max() > MAX_CELLS:
            raise ConfigError(f"simulated engraving on {part.name!r}: the marks span more than "
                              f"{MAX_CELLS * CELL_MM:g} mm; the simulator engraves smaller areas")
        removed = np.zeros((size[1], size[0]), np.float32)
        if nx:
            j, i = np.round((self.origin - lo) / CELL_MM).astype(int)
            removed[i:i + ny, j:j + nx] = self.removed
        self.restore(part, lo, removed)

    def restore(self, part: Workpiece, origin: np.ndarray, removed: np.ndarray) -> None:
        """Take ``removed`` (ny, nx) mm with its node (0, 0) at ``origin`` on ``part``."""
        self.origin, self.removed = np.asarray(origin, float), np.asarray(removed, np.float32)
        gx, gy = np.meshgrid(*self.nodes())
        self.top = part.height(*to_world(part, gx, gy))
        self.rate = _rate_field(self.material, self.seed, gx, gy)

    def depth_at(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Removed depth (mm) at part-frame points, bilinear; 0 off the grid."""
        ny, nx = self.removed.shape
        if nx == 0:
            return np.zeros(np.shape(u))
        fx = (np.asarray(u, float) - self.origin[0]) / CELL_MM
        fy = (np.asarray(v, float) - self.origin[1]) / CELL_MM
        return map_coordinates(self.removed, [fy.ravel(), fx.ravel()], order=1,
                               mode="constant", cval=0.0).reshape(np.shape(u)).astype(float)

    def mesh_depth(self) -> np.ndarray:
        """(ny, nx) the removed depth low-passed for a mesh on every :data:`MESH_STEP`-th
        node: each node the mean of the grid around it (a box of MESH_STEP cells, twice: a
        tent), so that no detail finer than the mesh (a hatch's 0.02 mm ridges) is sampled at
        one phase and shifts the surface the camera sees from the one removed."""
        k = np.convolve(np.ones(MESH_STEP), np.ones(MESH_STEP)) / MESH_STEP ** 2
        return cv2.sepFilter2D(self.removed, -1, k.astype(np.float32), k.astype(np.float32),
                               borderType=cv2.BORDER_REPLICATE)


def _rate_field(m: AblationMaterial, seed: int, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """(ny, nx) the blank's δ factor at part-frame nodes: one draw within ±rate_spread, times
    1 + grain × a mean-0, unit-amplitude field (bands across ``grain_deg``, or blotches)."""
    rng = np.random.default_rng([seed, 33, int(m.threshold_j_cm2 * 1000)])
    base = 1.0 + rng.uniform(-m.rate_spread, m.rate_spread)
    if m.grain == 0:
        return np.full(gx.shape, base, np.float32)
    k = 2 * np.pi / m.grain_mm
    if m.grain_deg is not None:
        a = np.radians(m.grain_deg + 90.0)
        s = gx * np.cos(a) + gy * np.sin(a)
        wobble = 0.3 * m.grain_mm * np.sin(2 * np.pi * (gx * np.cos(a + np.pi / 2)
                                                         + gy * np.sin(a + np.pi / 2)) / 7.0)
        g = np.sin(k * (s + wobble) + rng.uniform(0, 2 * np.pi))
    else:
        ang = rng.uniform(0, np.pi, 4)
        ph = rng.uniform(0, 2 * np.pi, 4)
        g = sum(np.sin(k * (gx * np.cos(a) + gy * np.sin(a)) + p) for a, p in zip(ang, ph)) / 2
    return (base * (1.0 + m.grain * g)).astype(np.float32)


def ablate(eng: Engraving, beam: MarkingBeam, uv: np.ndarray, focus_z: np.ndarray,
           pulses: np.ndarray, power_pct: float, frequency_khz: float,
           rng: np.random.Generator) -> bool:
    """Apply one burn: samples at part-frame ``uv`` (N, 2) mm with the z of the beam's focus
    on their beam ``focus_z`` (N,) mm and the ``pulses`` (N,) fired there, at ``power_pct`` of
    the beam's power and ``frequency_khz``. Returns whether anything was removed."""
    ok = np.isfinite(uv).all(1) & np.isfinite(focus_z) & (pulses > 0)
    if not ok.any() or power_pct <= 0:
        return False
    uv, focus_z, pulses = uv[ok], focus_z[ok], pulses[ok]
    m = eng.material
    energy_j = beam.power_w * power_pct / 100.0 / (frequency_khz * 1e3)
    j0, i0, j1, i1 = _window(eng, uv)
    xs, ys = eng.nodes(i0, i1, j0, j1)
    surface = eng.top[i0:i1, j0:j1] - eng.removed[i0:i1, j0:j1]
    fx, fy = ((uv - eng.origin) / CELL_MM - [j0, i0]).T
    z_now = map_coordinates(surface, [fy, fx], order=1, mode="nearest")
    w = beam.radius_mm(z_now - focus_z)
    jitter = 1.0 + 0.02 * rng.standard_normal()          # pulse energy stability, 2 % rms
    log_f = np.log(2 * energy_j * jitter / (np.pi * (w / 10.0) ** 2) / m.threshold_j_cm2)
    if not (log_f > 0).any():
        return False
    # cos θ of each cell from its slope (the beam is taken as vertical)
    gy_, gx_ = np.gradient(surface, CELL_MM)
    cos_t = 1.0 / np.sqrt(1.0 + gx_ ** 2 + gy_ ** 2)
    counts = _splat(fx, fy, pulses, surface.shape)
    wm, lm = float(np.median(w)), float(np.average(log_f, weights=pulses))
    r = np.arange(-int(np.ceil(2 * wm / CELL_MM)), int(np.ceil(2 * wm / CELL_MM)) + 1) * CELL_MM
    r2 = r[None, :] ** 2 + r[:, None] ** 2
    depth = _crater_sums(counts, cos_t, lm, wm, r2)
    depth *= m.penetration_um * 1e-3 * eng.rate[i0:i1, j0:j1]
    depth *= 1.0 + m.roughness * _smooth_noise(rng, depth.shape, wm / CELL_MM)
    depth = np.maximum(depth, 0.0)
    room = m.max_depth_mm - eng.removed[i0:i1, j0:j1]
    eng.removed[i0:i1, j0:j1] += np.minimum(depth, room).astype(np.float32)
    eng.version += 1
    return True


def _window(eng: Engraving, uv: np.ndarray) -> tuple[int, int, int, int]:
    """(j0, i0, j1, i1): the grid's nodes the burn at ``uv`` can reach (the crater's 3w)."""
    ny, nx = eng.removed.shape
    lo = np.floor((uv.min(0) - eng.origin) / CELL_MM - 12).astype(int)
    hi = np.ceil((uv.max(0) - eng.origin) / CELL_MM + 13).astype(int)
    return max(lo[0], 0), max(lo[1], 0), min(hi[0], nx), min(hi[1], ny)


def _splat(fx: np.ndarray, fy: np.ndarray, weight: np.ndarray, shape) -> np.ndarray:
    """(ny, nx) float32: ``weight`` spread bilinearly onto the nodes around (fx, fy)."""
    out = np.zeros(shape, np.float64)
    x0, y0 = np.floor(fx).astype(int), np.floor(fy).astype(int)
    ax, ay = fx - x0, fy - y0
    for dx, dy, wt in ((0, 0, (1 - ax) * (1 - ay)), (1, 0, ax * (1 - ay)),
                       (0, 1, (1 - ax) * ay), (1, 1, ax * ay)):
        xi, yi = x0 + dx, y0 + dy
        ok = (xi >= 0) & (yi >= 0) & (xi < shape[1]) & (yi < shape[0])
        np.add.at(out, (yi[ok], xi[ok]), (weight * wt)[ok])
    return out.astype(np.float32)


def _crater_sums(counts: np.ndarray, cos_t: np.ndarray, log_f: float, w: float,
                 r2: np.ndarray) -> np.ndarray:
    """(ny, nx) Σ over pulses of ln(F cos θ / F_th)⁺ per cell: the pulse ``counts`` convolved
    with the crater of each cos θ class the window holds, interpolated at each cell's cos θ."""
    c = np.clip(cos_t, _COS_CLASSES[-1], 1.0)
    k = np.clip(np.searchsorted(-_COS_CLASSES, -c), 1, len(_COS_CLASSES) - 1)
    layers = {}
    for j in np.unique(np.concatenate([k - 1, k])):
        kernel = np.maximum(log_f + np.log(_COS_CLASSES[j]) - 2 * r2 / w ** 2, 0.0)
        layers[j] = cv2.filter2D(counts, -1, kernel.astype(np.float32),
                                 borderType=cv2.BORDER_CONSTANT)
    hi, lo = _COS_CLASSES[k - 1], _COS_CLASSES[k]
    t = (c - lo) / (hi - lo)
    out = np.zeros(c.shape)
    for j in np.unique(k):
        sel = k == j
        out[sel] = t[sel] * layers[j - 1][sel] + (1 - t[sel]) * layers[j][sel]
    return out


def _smooth_noise(rng: np.random.Generator, shape, sigma_cells: float) -> np.ndarray:
    """Mean-0, unit-σ Gaussian noise correlated over ``sigma_cells``."""
    g = cv2.GaussianBlur(rng.standard_normal(shape).astype(np.float32), (0, 0),
                         max(sigma_cells, 0.5))
    s = float(g.std())
    return g / s if s > 0 else g


def engraved_part(part: Workpiece, eng: Engraving) -> Workpiece:
    """``part`` with the material ``eng`` removed: its top rebuilt as a height field whose grid
    takes the part's own nodes and the engraving's (every :data:`MESH_STEP`-th, the depth
    low-passed for it: :meth:`Engraving.mesh_depth`), so that the ray casting sees the
    pockets and their walls; its true height is the engraved surface."""
    if eng.removed.size == 0 or not np.any(eng.removed > 0):
        return part
    p = part.params
    u, v = to_part(part, part.vertices[:, 0], part.vertices[:, 1])
    z0 = float(part.vertices[:, 2].min())
    top = part.vertices[:, 2] > z0 + 1e-9
    xs, ys = eng.nodes()
    xs, ys = xs[::MESH_STEP], ys[::MESH_STEP]
    low = eng.mesh_depth()
    gx = np.unique(np.round(np.concatenate([u[top], xs]), 9))
    gy = np.unique(np.round(np.concatenate([v[top], ys]), 9))
    gx = gx[(gx >= u.min() - 1e-9) & (gx <= u.max() + 1e-9)]
    gy = gy[(gy >= v.min() - 1e-9) & (gy <= v.max() + 1e-9)]
    mx, my = np.meshgrid(gx, gy, indexing="ij")
    wx, wy = to_world(part, mx, my)
    fx, fy = (mx - eng.origin[0]) / CELL_MM, (my - eng.origin[1]) / CELL_MM
    height = part.height(wx, wy) - map_coordinates(low, [fy.ravel(), fx.ravel()], order=1,
                                                   mode="constant", cval=0.0).reshape(mx.shape)
    height = np.where(np.isfinite(height), height, z0 + 1e-3)
    verts, tris = meshes.heightfield_block(gx, gy, np.maximum(height, z0 + 1e-3), z0)
    verts = meshes.place(verts, p.get("x", 0.0), p.get("y", 0.0), p.get("angle_deg", 0.0))
    base_height = part.height_fn

    def engraved_height(x, y):
        uu, vv = to_part(part, x, y)
        return base_height(x, y) - eng.depth_at(uu, vv)
    return Workpiece(part.name, verts, tris, part.params, engraved_height)
