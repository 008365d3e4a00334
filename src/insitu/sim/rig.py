"""The simulated rig: a *true* geometry, and the *operator's* calibration that differs from it
by realistic calibration errors — so measurement errors are real and calibration has work.

Default rig: after Li et al. §3.1 — 5 MPix camera (2448 × 2048, 3.45 µm pixels) with a 16 mm
lens on the side of the head, ~200 mm field of view at ~360 mm; scan head with d = 350 mm.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from insitu.formats.rig import ScanHeadGeometry
from insitu.geometry.beams import ScanHeadOptics, TwoMirrorHead
from insitu.geometry.camera import CameraModel, rotation_about
from insitu.geometry.distortion import FieldDistortion, NoDistortion, PolynomialFieldDistortion
from insitu.rig.model import RigModel

PIXEL_PITCH_MM = 0.00345
LENS_FOCAL_MM = 16.0
FULL_SIZE = (2448, 2048)


@dataclass(frozen=True)
class Optics:
    """Light and sensor physics of the simulated rig.

    beam_waist_mm: 1/e² radius of the focused laser at the focal plane; wavelength_mm for its
    Rayleigh range. f_number and camera focus distance set the camera's blur. Sensor: gain in
    electrons per DN, read noise and dark level in DN, fixed-pattern gain and offsets (drawn
    from the rig's seed: one camera, one pattern), 8-bit output. Sources: docs/simulator.md.
    """

    beam_waist_mm: float = 0.15
    wavelength_mm: float = 680e-6
    f_number: float = 8.0
    camera_focus_mm: float = 362.0
    line_power: float = 2.5e4       # DN·mm² reaching the sensor per mm of line, for albedo 1
    spot_power: float = 6.0e3       # DN·mm² for a whole spot, albedo 1
    ambient_dn: float = 30.0        # room light on an albedo-1 surface facing up
    ambient_gradient: float = 0.25  # room light's fall-off across the field, ± fraction
    lamp_share: float = 0.0         # of the room light, the share from one lamp (the rest
    lamp_deg: tuple[float, float] = (30.0, 45.0)   # diffuse): its azimuth, elevation; the
    #                                 parts cast shadows in its light (docs/simulator.md)
    speckle_contrast: float = 0.35  # image-plane (subjective) speckle; along-line: Material
    secondary_fraction: float = 0.25
    electrons_per_dn: float = 8.0
    read_noise_dn: float = 1.2
    dark_dn: float = 3.0
    prnu: float = 0.01              # fixed pattern: per-pixel gain σ (fraction)
    dsnu_dn: float = 0.6            # fixed pattern: per-pixel offset σ, DN
    column_dn: float = 0.4          # fixed pattern: per-column offset σ, DN

    @property
    def rayleigh_mm(self) -> float:
        return np.pi * self.beam_waist_mm**2 / self.wavelength_mm

    def beam_radius_mm(self, defocus_mm: np.ndarray) -> np.ndarray:
        """1/e² beam radius at a distance ``defocus_mm`` from the focus along the beam."""
        return self.beam_waist_mm * np.sqrt(1.0 + (np.asarray(defocus_mm) / self.rayleigh_mm) ** 2)


NOMINAL_HEAD = ScanHeadGeometry(lens="non-telecentric", pivot_height_mm=350.0,
                                mirror_distance_mm=350.0, mirror_separation_mm=12.0,
                                field_size_mm=(200.0, 200.0), z_range_mm=(-25.0, 25.0))
"""What the operator knows of the default head: its nominal geometry."""


@dataclass(frozen=True)
class SimRig:
    """True camera and head, and the rig model its operator would have: the camera as
    calibrated (with realistic errors) and the head's nominal geometry."""

    camera: CameraModel                 # true
    head: TwoMirrorHead                 # true kinematics
    distortion: FieldDistortion         # true field distortion
    operator: RigModel                  # what the operator knows
    optics: Optics = field(default_factory=Optics)
    seed: int = 0

    @property
    def beams(self) -> ScanHeadOptics:
        """The true beams: where the laser really goes for a command."""
        return ScanHeadOptics(self.head, self.distortion)

    def ideal_correction(self, iterations: int = 30):
        """The flawless field correction, from the truth: (N, 2) targets Q on z = 0, mm →
        commands K with K + δ(K) = Q. What a perfect field calibration would give (for
        benchmarks that separate the calibration's error from the rest)."""
        def correct(q: np.ndarray) -> np.ndarray:
            q = np.asarray(q, np.float64)
            k = q.copy()
            for _ in range(iterations):
                k = q - self.distortion(k)
            return k
        return correct

    def truth_dict(self) -> dict:
        dist = self.distortion
        return {
            "seed": self.seed,
            "camera": self.camera.to_dict(),
            "scan_head": {"mirror_distance_mm": self.head.mirror_distance_mm,
                          "mirror_separation_mm": self.head.mirror_separation_mm,
                          "field_distortion": dist.to_dict() if hasattr(dist, "to_dict")
                          else {"type": "none"}},
            "optics": {k: getattr(self.optics, k) for k in self.optics.__dataclass_fields__},
        }


def _camera_pose(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Camera on the side of the head (−x), ~24° off vertical, mounted slightly imperfectly."""
    base = CameraModel.look_at(1, 1, np.eye(3), np.zeros(5), [-150.0, 0.0, 330.0],
                               [0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    wobble = rotation_about(rng.normal(size=3), np.deg2rad(0.6))
    R = wobble @ base.R
    centre = base.centre_world + rng.normal(0.0, 1.0, 3)
    return R, -R @ centre


def default_rig(seed: int = 0, binning: int = 1, distortion_rms_mm: float = 0.8,
                calibration_errors: bool = True) -> SimRig:
    """The embedded default rig. ``binning`` divides the image size (small test frames)."""
    rng = np.random.default_rng(seed)
    w, h = FULL_SIZE[0] // binning, FULL_SIZE[1] // binning
    f = LENS_FOCAL_MM / PIXEL_PITCH_MM / binning
    K = np.array([[f, 0, (w - 1) / 2 + rng.normal(0, 6 / binning)],
                  [0, f, (h - 1) / 2 + rng.normal(0, 6 / binning)], [0, 0, 1]])
    dist = np.array([-0.09, 0.15, 0.0, 0.0, -0.06]) + rng.normal(0, [0.01, 0.02, 3e-4, 3e-4, 0.01])
    R, t = _camera_pose(rng)
    camera = CameraModel(w, h, K, dist, R, t)
    head = TwoMirrorHead(350.0 + rng.normal(0, 0.6), 12.0 + rng.normal(0, 0.3))
    distortion = (PolynomialFieldDistortion.random(rng, distortion_rms_mm)
                  if distortion_rms_mm > 0 else NoDistortion())
    operator = operator_calibration(camera, rng) if calibration_errors else camera
    return SimRig(camera, head, distortion, RigModel(operator, NOMINAL_HEAD), seed=seed)


def operator_calibration(camera: CameraModel, rng: np.random.Generator) -> CameraModel:
    """The true camera seen through a good but imperfect calibration: focal length ~0.03 %,
    principal point ~0.4 px, distortion, pose ~0.02° and ~0.08 mm off."""
    px = camera.K[0, 0] * PIXEL_PITCH_MM / LENS_FOCAL_MM  # 1 / binning
    K = camera.K.copy()
    K[0, 0] *= 1 + rng.normal(0, 3e-4)
    K[1, 1] *= 1 + rng.normal(0, 3e-4)
    K[:2, 2] += rng.normal(0, 0.4 * px, 2)
    dist = camera.dist + rng.normal(0, [2e-3, 5e-3, 3e-5, 3e-5, 5e-3])
    dR = rotation_about(rng.normal(size=3), np.deg2rad(0.02))
    R = dR @ camera.R
    centre = camera.centre_world + rng.normal(0, 0.08, 3)
    return replace(camera, K=K, dist=dist, R=R, t=-R @ centre)


def move_camera(rig: SimRig, angle_deg: float, shift_mm: float, seed: int = 0) -> SimRig:
    """The rig after its camera was knocked: the true camera turned by ``angle_deg`` about a
    random axis through its centre and its centre moved by ``shift_mm`` in a random direction
    (both drawn from ``seed``). The operator's calibration still describes the old pose."""
    rng = np.random.default_rng([seed, 404])
    cam = rig.camera
    R = rotation_about(rng.normal(size=3), np.deg2rad(angle_deg)) @ cam.R
    shift = rng.normal(size=3)
    centre = cam.centre_world + shift_mm * shift / np.linalg.norm(shift)
    return replace(rig, camera=replace(cam, R=R, t=-R @ centre))
