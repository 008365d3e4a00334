"""Physically based frames of the simulated camera: laser lines and pilot spots.

A line frame: the commanded line is sampled densely; each sample's *true* beam is traced to its
first surface hit (shadowing), kept if the camera sees it (occlusion), weighted by the surface's
reflectance toward the camera (textured Lambertian + Phong lobe), projected through the *true*
camera with its distortion and splatted as a pixel-integrated Gaussian whose width is the laser
footprint (growing out of focus) blurred by the lens (diffraction, depth of field), its
brightness modulated along the line by correlated gamma-distributed speckle blotches (per
material). Secondary light, traced with rays: the beam's specular reflection lights where it
lands (a wall next to a floor), and the camera sees the lit surface mirrored in specular faces
(step and hole walls). Then image-plane speckle (pupil-filtered complex field), textured and
shaded ambient light, fixed-pattern gain and offsets, shot and read noise, saturation and
8-bit quantisation. Parameters and their sources: docs/simulator.md.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree
from scipy.special import erf, gammaincinv, ndtr

from insitu.geometry.beams import line_commands
from insitu.sim.rig import LENS_FOCAL_MM, PIXEL_PITCH_MM, SimRig
from insitu.sim.room_light import ambient_image
from insitu.sim.scene import Scene

NOMINAL_EXPOSURE_MS = 10.0
_SAMPLE_SPACING_PX = 0.3
_MAP_SCALE = 2          # the camera's mirror map: 1/2 of the frame's size
_MIRROR_SUB = 3         # mirror pixels: 3 × 3 rays per pixel (the line is narrower than a pixel)


class Renderer:
    """Renders frames of ``rig``'s true camera looking at ``scene``.

    ``ideal=True`` leaves out speckle, texture, secondary light, ambient light, noise and
    quantisation and returns float32 frames: the geometry alone, for tests of where the line
    must be.
    """

    def __init__(self, rig: SimRig, scene: Scene, seed: int = 0, ideal: bool = False):
        self.rig, self.scene, self.ideal = rig, scene, ideal
        self.cam = rig.camera
        self.rng = np.random.default_rng(seed)
        self._binning = LENS_FOCAL_MM / PIXEL_PITCH_MM / self.cam.K[0, 0]
        self._pitch_mm = PIXEL_PITCH_MM * self._binning
        self._ambient: np.ndarray | None = None
        self._mirror: tuple | None = None
        self._speckle: np.ndarray | None = None
        self._fpn: tuple[np.ndarray, np.ndarray] | None = None

    def set_scene(self, scene: Scene) -> None:
        """The parts moved (stage, new workpiece): keep the sensor, redo the ambient light."""
        self.scene, self._ambient, self._mirror = scene, None, None

    # -- public frames ----------------------------------------------------------------------
    def ambient_frame(self, exposure_ms: float = NOMINAL_EXPOSURE_MS) -> np.ndarray:
        """(H, W) frame with the laser off."""
        return self._finish(np.zeros((self.cam.height, self.cam.width), np.float32), exposure_ms)

    def line_frame(self, start, end, exposure_ms: float = NOMINAL_EXPOSURE_MS,
                   focus_z: float = 0.0) -> np.ndarray:
        """(H, W) uint8 frame (float32 if ideal) of the line commanded from start to end, mm."""
        return self._finish(self._line_signal(start, end, exposure_ms, focus_z), exposure_ms)

    def lines_frame(self, lines, exposure_ms: float = NOMINAL_EXPOSURE_MS,
                    focus_z: float = 0.0) -> np.ndarray:
        """(H, W) frame of the K ``lines`` ((start, end) mm each) drawn in turn during one
        exposure: each line with the light of ``exposure_ms / K``, the room light of the
        whole exposure (the frame's sensor noise once)."""
        share = exposure_ms / len(lines)
        signal = self._line_signal(*lines[0], share, focus_z)
        for a, b in lines[1:]:
            signal += self._line_signal(a, b, share, focus_z)
        return self._finish(signal, exposure_ms)

    def _line_signal(self, start, end, exposure_ms: float, focus_z: float) -> np.ndarray:
        """(H, W) float32 light of the line start → end (mm) over ``exposure_ms``, before
        the sensor: the beam's hits, their secondary light and mirror images."""
        start, end = np.asarray(start, float), np.asarray(end, float)
        length = float(np.linalg.norm(end - start))
        px_per_mm = self.cam.K[0, 0] / 250.0  # generous: the closest surfaces are ~300 mm away
        n = max(int(np.ceil(length * px_per_mm / _SAMPLE_SPACING_PX)) + 1, 2)
        cmd = line_commands(start, end, n)
        energy = self.rig.optics.line_power * length / (n - 1) * exposure_ms / NOMINAL_EXPOSURE_MS
        signal = self._beam_signal(cmd, np.full(n, energy), focus_z, secondary=True)
        if not self.ideal:
            signal += self._mirror_image(cmd, energy * (n - 1) / length, focus_z)
        return signal

    def spot_frame(self, xy, exposure_ms: float = NOMINAL_EXPOSURE_MS, focus_z: float = 0.0,
                   n_rays: int = 800) -> np.ndarray:
        """(H, W) frame of the pilot laser commanded to ``xy`` (mm on z = 0)."""
        origins, dirs = self.rig.beams.rays(np.asarray(xy, float).reshape(1, 2))
        o, d = origins[0], dirs[0]
        # Sub-rays filling the Gaussian beam: parallel offsets across the beam at its focus.
        e1 = np.cross(d, [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(d, e1)
        s_focus = (focus_z - o[2]) / d[2]
        w = float(self.rig.optics.beam_radius_mm(0.0))
        off = self.rng.normal(0.0, w / 2, (n_rays, 2)) if not self.ideal else \
            _gauss_quadrature_disc(n_rays) * (w / 2)
        sub_o = o + s_focus * d - 50.0 * d + off[:, :1] * e1 + off[:, 1:] * e2
        sub_d = np.tile(d, (n_rays, 1))
        energy = np.full(n_rays, self.rig.optics.spot_power / n_rays
                         * exposure_ms / NOMINAL_EXPOSURE_MS)
        signal = self._splat_hits(sub_o, sub_d, energy, focus_z, beam_blur=False)
        return self._finish(signal, exposure_ms)

    # -- tracing ----------------------------------------------------------------------------
    def _beam_signal(self, cmd: np.ndarray, energy: np.ndarray, focus_z: float,
                     secondary: bool) -> np.ndarray:
        origins, dirs = self.rig.beams.rays(cmd)
        return self._splat_hits(origins, dirs, energy, focus_z, beam_blur=True,
                                secondary=secondary)

    def _splat_hits(self, origins, dirs, energy, focus_z, beam_blur: bool,
                    secondary: bool = False) -> np.ndarray:
        H, W = self.cam.height, self.cam.width
        img = np.zeros(H * W, np.float64)
        hits = self.scene.cast(origins, dirs)
        if not hits.hit.any():
            return img.reshape(H, W).astype(np.float32)
        p, nrm, part = hits.points[hits.hit], hits.normals[hits.hit], hits.part[hits.hit]
        o, d, e = origins[hits.hit], dirs[hits.hit], energy[hits.hit]
        # distance from the focus along each beam (the dynamic focus sits on z = focus_z)
        s_hit = np.einsum("ij,ij->i", p - o, d)
        s_focus = (focus_z - o[:, 2]) / d[:, 2]
        w = self.rig.optics.beam_radius_mm(s_hit - s_focus) if beam_blur else np.zeros(len(p))
        cos_in = np.abs(np.einsum("ij,ij->i", d, nrm))
        if beam_blur and not self.ideal:
            e = e * self._blotches(p, part)
        self._add(img, p, nrm, part, e, w / 2 / np.sqrt(np.maximum(cos_in, 0.2)), d)
        if secondary and not self.ideal:
            self._add_secondary(img, p, nrm, part, e, w, d)
        return img.reshape(H, W).astype(np.float32)

    def _blotches(self, p: np.ndarray, part: np.ndarray) -> np.ndarray:
        """(N,) mean-1 along-line speckle factors for the line's hit points p (N, 3) in line
        order: a Gaussian process in arc length on the surface (1/e correlation at the
        material's length) mapped to a gamma law of the material's coefficient of variation."""
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        corr = self.scene.material_field(part, "speckle_corr_mm", 0.25)
        cv = self.scene.material_field(part, "speckle_cv", 0.25)
        step = corr.min() / 6
        grid = self.rng.standard_normal(int(s[-1] / step) + 25)
        sigma = corr.min() / 2 / step                    # exp(−τ²/4σ²) = 1/e at τ = corr
        k = np.exp(-0.5 * (np.arange(-int(4 * sigma) - 1, int(4 * sigma) + 2) / sigma) ** 2)
        g = np.convolve(grid, k / np.sqrt((k**2).sum()), mode="same")
        shape = 1.0 / cv**2
        return gammaincinv(shape, ndtr(np.interp(s / step + 12, np.arange(len(g)), g))) / shape

    def _mirror_image(self, cmd: np.ndarray, line_density: float, focus_z: float) -> np.ndarray:
        """(H, W) light of the line seen mirrored in specular faces: for each camera pixel whose
        ray meets a mirror-like face and, reflected, lands on a surface point Q, the radiance of
        Q under the line's light sheet (Gaussian profile across it) times the face's mirror
        fraction, averaged over the pixel. ``line_density``: energy per mm of line."""
        H, W = self.cam.height, self.cam.width
        pix, q, weight = self._mirror_map()
        if not len(q):
            return np.zeros((H, W), np.float32)
        origins, dirs = self.rig.beams.rays(cmd[[0, len(cmd) // 2, -1]])
        normal = np.cross(dirs[0], dirs[-1])
        normal /= np.linalg.norm(normal)
        dist = (q - origins[1]) @ normal                  # from the light sheet, mm
        w = float(self.rig.optics.beam_radius_mm(0.0))
        near = np.abs(dist) < 3 * w
        if not near.any():
            return np.zeros((H, W), np.float32)
        hits = self.scene.cast(*self.rig.beams.rays(cmd[:: max(len(cmd) // 400, 1)]))
        lit_pts = hits.points[hits.hit]
        if not len(lit_pts):
            return np.zeros((H, W), np.float32)
        gap, _ = cKDTree(lit_pts).query(q[near], distance_upper_bound=3 * w)
        sel = np.flatnonzero(near)[np.isfinite(gap)]      # lit by the beam, not in its shadow
        if not len(sel):
            return np.zeros((H, W), np.float32)
        sigma = w / 2
        irr = line_density * np.exp(-0.5 * (dist[sel] / sigma) ** 2) / (np.sqrt(2 * np.pi) * sigma)
        # a surface seen in the camera gives irradiance × albedo × (362 / f)² / binning² DN per
        # pixel (the splat of _add integrated over a pixel's footprint), here times the mirror
        img = np.bincount(pix[sel], irr * weight[sel] * (362.0 / self.cam.K[0, 0]) ** 2
                          / self._binning**2, minlength=H * W).reshape(H, W).astype(np.float32)
        v, u = np.divmod(pix[sel], W)
        v0, v1, u0, u1 = max(v.min() - 4, 0), v.max() + 5, max(u.min() - 4, 0), u.max() + 5
        img[v0:v1, u0:u1] = cv2.GaussianBlur(img[v0:v1, u0:u1], (0, 0), 0.7)  # rough face
        return img

    def _mirror_map(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per scene, for 3 × 3 rays in each pixel that sees a mirror-like face: the frame's
        flat pixel index (M,), the point Q (M, 3) the ray meets reflected, and the weight (M,) =
        the face's mirror fraction × Q's albedo / 9."""
        if self._mirror is None:
            self._camera_maps()
        return self._mirror

    def _add_secondary(self, img, p, nrm, part, e, w, d) -> None:
        """The specular part of each beam, reflected once, lights where it lands."""
        spec, _ = self.scene.material_arrays(part)
        refl = d - 2 * np.einsum("ij,ij->i", d, nrm)[:, None] * nrm
        hits = self.scene.cast(p + 1e-3 * nrm, refl, max_t=150.0, lift_to_z=None)
        sel = hits.hit & (spec > 0)
        if not sel.any():
            return
        q = hits.points[sel]
        travel = np.linalg.norm(q - p[sel], axis=1)
        e2 = e[sel] * spec[sel] * self.rig.optics.secondary_fraction
        sigma = w[sel] / 2 + 0.02 * travel  # the rough surface spreads the reflected beam
        self._add(img, q, hits.normals[sel], hits.part[sel], e2, sigma, refl[sel])

    def _add(self, img, p, nrm, part, energy, sigma_mm, d_in) -> None:
        """Splat light arriving at surface points p (N, 3) along d_in as the camera sees it."""
        eye = self.cam.centre_world
        vis = self.scene.visible_from(p, nrm, eye)
        if not vis.any():
            return
        p, nrm, part, energy, sigma_mm, d_in = (a[vis] for a in (p, nrm, part, energy,
                                                                 sigma_mm, d_in))
        to_eye = eye - p
        r = np.linalg.norm(to_eye, axis=1)
        v = to_eye / r[:, None]
        cos_view = np.einsum("ij,ij->i", v, nrm)
        refl = d_in - 2 * np.einsum("ij,ij->i", d_in, nrm)[:, None] * nrm
        spec, shin = self.scene.material_arrays(part)
        lobe = spec * (shin + 2) / 2 * np.maximum(np.einsum("ij,ij->i", refl, v), 0.0) ** shin
        if self.ideal:
            rho = np.array([self.scene.materials[i].albedo for i in part])
            lobe = 0.0
        else:
            rho = self.scene.albedo(p, part)
        radiance = energy * (rho * cos_view + lobe) * (362.0 / r) ** 2 / self._binning**2
        uv = self.cam.project(p)
        z_cam = self.cam.to_camera(p)[:, 2]
        sigma_px = np.sqrt((sigma_mm * self.cam.K[0, 0] / z_cam) ** 2 + self._lens_blur_px(z_cam) ** 2)
        _splat(img, self.cam.width, self.cam.height, uv, sigma_px, radiance)

    def _lens_blur_px(self, depth_mm: np.ndarray) -> np.ndarray:
        return lens_blur_px(self.rig, depth_mm)

    # -- sensor -----------------------------------------------------------------------------
    def _finish(self, laser: np.ndarray, exposure_ms: float) -> np.ndarray:
        if self.ideal:
            return laser
        o = self.rig.optics
        H, W = laser.shape
        gain, offset = self._fixed_pattern()
        speckle = self._speckle_field()
        dv, du = self.rng.integers(0, speckle.shape[0] - H), self.rng.integers(0, speckle.shape[1] - W)
        laser *= speckle[dv:dv + H, du:du + W]
        laser += self._ambient_image() * np.float32(exposure_ms / NOMINAL_EXPOSURE_MS)
        laser *= gain
        laser += offset
        var = laser * np.float32(1.0 / o.electrons_per_dn) + np.float32(o.read_noise_dn**2)
        noise = self.rng.standard_normal((H, W), dtype=np.float32)
        laser += noise * np.sqrt(var)
        return np.clip(laser + 0.5, 0, 255).astype(np.uint8)

    def _speckle_field(self) -> np.ndarray:
        """Fully developed speckle from a pupil-filtered complex field, contrast reduced to the
        optics' value; mean 1. Made once, larger than the frame; frames take shifted windows."""
        if self._speckle is None:
            o = self.rig.optics
            grain = 2.44 * o.wavelength_mm * o.f_number / self._pitch_mm
            H, W = self.cam.height + 64, self.cam.width + 64
            field = self.rng.standard_normal((H, W)) + 1j * self.rng.standard_normal((H, W))
            fy, fx = np.fft.fftfreq(H)[:, None], np.fft.fftfreq(W)[None, :]
            pupil = (fx**2 + fy**2) <= (1.0 / grain) ** 2
            amp = np.fft.ifft2(np.fft.fft2(field) * pupil)
            intensity = np.abs(amp) ** 2
            intensity /= intensity.mean()
            c = o.speckle_contrast
            self._speckle = (1 - c + c * intensity).astype(np.float32)
        return self._speckle

    def _fixed_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """(H, W) per-pixel gain (mean 1) and offset (dark level + pixel and column offsets,
        DN) of this camera: drawn from the rig's seed, the same in every frame and renderer."""
        if self._fpn is None:
            o, H, W = self.rig.optics, self.cam.height, self.cam.width
            rng = np.random.default_rng([self.rig.seed, 0xF1C5])
            gain = 1.0 + o.prnu * rng.standard_normal((H, W), dtype=np.float32)
            offset = (o.dark_dn + o.dsnu_dn * rng.standard_normal((H, W), dtype=np.float32)
                      + o.column_dn * rng.standard_normal((1, W), dtype=np.float32))
            self._fpn = gain.astype(np.float32), offset.astype(np.float32)
        return self._fpn

    def _ambient_image(self) -> np.ndarray:
        """(H, W) room light on the scene as the camera sees it (textured albedo, shading by
        the normal, a fall-off across the field), DN at the nominal exposure."""
        if self._ambient is None:
            self._camera_maps()
        return self._ambient

    def _camera_maps(self) -> None:
        """One ray cast of the camera's pixels at 1/2 size gives the ambient image
        (:func:`insitu.sim.room_light.ambient_image`) and the mirror map: where a pixel's ray
        meets a face with a mirror fraction and its reflection meets a surface, the pixel is
        cast again with 3 × 3 rays and the points they meet reflected are kept."""
        H, W = self.cam.height, self.cam.width
        w = (W + _MAP_SCALE - 1) // _MAP_SCALE
        self._ambient, hits, dirs = ambient_image(self.rig, self.scene, _MAP_SCALE,
                                                  self._lens_blur_px)
        pts, part, nrm = hits.points[hits.hit], hits.part[hits.hit], hits.normals[hits.hit]
        # mirror pixels: every frame pixel of a map pixel on a mirror-like face, sub-sampled
        cell = np.flatnonzero(hits.hit)[self.scene.material_field(part, "mirror") > 0]
        if len(cell):       # only cells whose reflection meets a surface: sub-sample those
            c_hit = hits.hit.copy()
            c_hit[:] = False
            c_hit[cell] = True
            sel = c_hit[hits.hit]
            n = nrm[sel]
            refl = dirs[cell] - 2 * np.einsum("ij,ij->i", dirs[cell], n)[:, None] * n
            cell = cell[self.scene.cast(pts[sel] + 1e-3 * n, refl, max_t=300.0,
                                        lift_to_z=None).hit]
        if not len(cell):
            self._mirror = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0))
            return
        sub = (np.arange(_MIRROR_SUB) + 0.5) / _MIRROR_SUB - 0.5
        blk = np.arange(_MAP_SCALE)
        du = (blk[:, None] + sub[None, :]).ravel()
        fu = (cell % w)[:, None, None] * _MAP_SCALE + du[None, :, None] + 0 * du[None, None, :]
        fv = (cell // w)[:, None, None] * _MAP_SCALE + du[None, None, :] + 0 * du[None, :, None]
        uv = np.column_stack([fu.ravel(), fv.ravel()])
        uv = uv[(uv[:, 0] < W - 0.5) & (uv[:, 1] < H - 0.5)]
        origin, dirs = self.cam.rays(uv)
        first = self.scene.cast(np.tile(origin, (len(dirs), 1)), dirs)
        mirror = self.scene.material_field(first.part, "mirror")
        m = first.hit & (mirror > 0)
        d, n = dirs[m], first.normals[m]
        refl = d - 2 * np.einsum("ij,ij->i", d, n)[:, None] * n
        second = self.scene.cast(first.points[m] + 1e-3 * n, refl, max_t=300.0, lift_to_z=None)
        ok = second.hit
        q, qp = second.points[ok], second.part[ok]
        pix = np.rint(uv[m][ok]).astype(np.int64)
        self._mirror = (pix[:, 1] * W + pix[:, 0], q,
                        mirror[m][ok] * self.scene.albedo(q, qp) / _MIRROR_SUB**2)


def lens_blur_px(rig: SimRig, depth_mm) -> np.ndarray:
    """Gaussian σ of ``rig``'s lens PSF, px of its camera, at ``depth_mm`` along its axis:
    diffraction plus defocus (depth of field)."""
    o = rig.optics
    pitch = LENS_FOCAL_MM / rig.camera.K[0, 0]          # mm a pixel, binning included
    diffraction = 0.42 * o.wavelength_mm * o.f_number / pitch
    f, s = LENS_FOCAL_MM, o.camera_focus_mm
    blur_circle = f * f / (o.f_number * (s - f)) * np.abs(depth_mm - s) / depth_mm
    return np.sqrt(diffraction**2 + (blur_circle / 4 / pitch) ** 2)


def _splat(img: np.ndarray, W: int, H: int, uv: np.ndarray, sigma: np.ndarray,
           energy: np.ndarray) -> None:
    """Add pixel-integrated isotropic Gaussians (energy each, σ px) at uv (N, 2) into the flat
    (H·W,) image."""
    ok = np.isfinite(uv).all(1) & (energy > 0)
    uv, sigma, energy = uv[ok], sigma[ok], energy[ok]
    if not len(uv):
        return
    r = int(np.ceil(3.5 * sigma.max()))
    offs = np.arange(-r, r + 1)
    iu = np.rint(uv[:, 0]).astype(np.int64)[:, None] + offs   # (N, 2r+1)
    iv = np.rint(uv[:, 1]).astype(np.int64)[:, None] + offs
    s = (np.sqrt(2.0) * sigma)[:, None]
    wu = 0.5 * (erf((iu + 0.5 - uv[:, :1]) / s) - erf((iu - 0.5 - uv[:, :1]) / s))
    wv = 0.5 * (erf((iv + 0.5 - uv[:, 1:]) / s) - erf((iv - 0.5 - uv[:, 1:]) / s))
    wu *= (iu >= 0) & (iu < W)
    wv *= (iv >= 0) & (iv < H)
    weights = (wv * energy[:, None])[:, :, None] * wu[:, None, :]        # (N, 2r+1, 2r+1)
    idx = np.clip(iv, 0, H - 1)[:, :, None] * W + np.clip(iu, 0, W - 1)[:, None, :]
    img += np.bincount(idx.ravel(), weights.ravel(), minlength=H * W)


def _gauss_quadrature_disc(n: int) -> np.ndarray:
    """(n, 2) deterministic standard-normal samples (a sunflower spiral through the inverse
    CDF): the ideal renderer's noise-free beam profile."""
    k = np.arange(n) + 0.5
    radius = np.sqrt(-2.0 * np.log(1.0 - k / n))
    angle = k * np.pi * (3.0 - np.sqrt(5.0))
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
