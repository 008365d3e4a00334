"""The camera's pose re-estimated from laser spots after it moved (after the BGLS on-site
recalibration, Wang et al. 2018 §2.3), with a single camera whose intrinsics are unchanged.

The head's beams are known in the world (scan-head) frame — for us from its beam model (the
nominal two-mirror head, or one corrected by a field calibration) instead of the paper's
off-site fitted beams. Spots are commanded to a grid on the flat plate at two (or more) known
heights z_i; the camera sees spot k of plate i at pixel uv_ik. Unknown: T_cam_world = [R | t].

The paper measures the spots in 3-D with its stereo pair; one camera cannot, so the plate
stands in for the second view: the spots of plate i lie where the beams cross z = z_i, so the
homography from those plate points to the undistorted image gives the plate's pose and the
spots in camera coordinates p_ik (Zhang's decomposition). Then, as the paper:

* §2.3.1 rotation: the camera-frame segment p_2k − p_1k is the beam's direction v_k turned by
  R, so (Cayley/Rodrigues, R₀ = (I + S)(I − S)⁻¹, S = [s]×) v − w = s × (v + w) is linear in
  s; least squares over all beams. (Cayley cannot express half-turns and our camera looks
  down, ~160° from the world axes: we solve for the rotation left after plate 1's, which is
  small.)
* §2.3.2 translation: p_ik = R (o_k + τ_ik v_k) + t for beam points o_k; linear in (τ, t) —
  the paper's Eq. 9, solved here with the τ eliminated (the same least-squares solution).
* §2.3.3 refinement (Eq. 3): scipy ``least_squares`` (Levenberg–Marquardt) over the rotation
  vector and t, minimising the distance from each spot — its camera ray met with the plate
  z = z_i — to its beam. The point-to-beam RMS is the fit's residual; the pose's 1-σ comes
  from the Jacobian at the solution.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

from insitu.errors import CalibrationError
from insitu.geometry.beams import BeamModel
from insitu.geometry.camera import CameraModel

MIN_SPOTS_PER_PLATE = 6


@dataclass(frozen=True)
class SpotObservations:
    """Spots seen by the camera. cmd (N, 2): commands, mm on z = 0; plate_z (N,): plate
    height of each, world mm; uv (N, 2): spot centres, distorted pixels."""

    cmd: np.ndarray
    plate_z: np.ndarray
    uv: np.ndarray

    def __post_init__(self):
        for name, cols in (("cmd", 2), ("plate_z", None), ("uv", 2)):
            a = np.asarray(getattr(self, name), np.float64)
            object.__setattr__(self, name, a.reshape(-1, cols) if cols else a.ravel())
        if not len(self.cmd) == len(self.plate_z) == len(self.uv):
            raise ValueError("cmd, plate_z and uv must have the same length")


@dataclass(frozen=True)
class PoseFromSpots:
    """R (3, 3), t (3,) mm: T_cam_world. ``residuals_mm`` (N,): spot-to-beam distances.
    ``rms_mm``: their RMS. ``R0``, ``t0``: the linear estimate. ``std_rot_deg`` (3,) and
    ``std_t_mm`` (3,): 1-σ of the rotation vector and of t."""

    R: np.ndarray
    t: np.ndarray
    residuals_mm: np.ndarray
    rms_mm: float
    R0: np.ndarray
    t0: np.ndarray
    std_rot_deg: np.ndarray
    std_t_mm: np.ndarray


def beam_points(beams: BeamModel, cmd: np.ndarray, z: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Beam origins (N, 3), unit directions (N, 3), and where each meets z = z_k (N, 3), mm."""
    o, d = beams.rays(np.asarray(cmd, np.float64).reshape(-1, 2))
    s = (np.asarray(z, np.float64) - o[:, 2]) / d[:, 2]
    return o, d, o + s[:, None] * d


def _skew(v: np.ndarray) -> np.ndarray:
    """(N, 3) → (N, 3, 3) cross-product matrices [v]×."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], -1),
                     np.stack([v[:, 2], z, -v[:, 0]], -1),
                     np.stack([-v[:, 1], v[:, 0], z], -1)], 1)


def cayley(s: np.ndarray) -> np.ndarray:
    """R = (I + S)(I − S)⁻¹ with S = [s]× (the paper's Eq. 5)."""
    S = _skew(np.asarray(s, float).reshape(1, 3))[0]
    return (np.eye(3) + S) @ np.linalg.inv(np.eye(3) - S)


def rotation_between(w: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Least-squares R with v_k ≈ R w_k (unit (N, 3) each), linear in the Cayley vector s:
    v − w = s × (v + w) = −[v + w]× s (§2.3.1)."""
    A = -_skew(v + w).reshape(-1, 3)
    s, *_ = np.linalg.lstsq(A, (v - w).ravel(), rcond=None)
    return cayley(s)


def _plate_pose(xy: np.ndarray, z: float, norm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pose (R, t) of the world from the homography plate points (x, y) at height z →
    normalised image points (Zhang's decomposition; R made orthonormal)."""
    H, _ = cv2.findHomography(xy, norm, 0)
    if H is None:
        raise CalibrationError("the spots of one plate height do not span a plane "
                               "(collinear commands?)")
    lam = 2.0 / (np.linalg.norm(H[:, 0]) + np.linalg.norm(H[:, 1]))
    if H[2, 2] * lam < 0:          # the plate is in front of the camera
        lam = -lam
    r1, r2, h3 = lam * H[:, 0], lam * H[:, 1], lam * H[:, 2]
    U, _, Vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    R = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
    return R, h3 - z * R[:, 2]


def linear_pose(obs: SpotObservations, camera: CameraModel, beams: BeamModel
                ) -> tuple[np.ndarray, np.ndarray]:
    """The paper's two-step linear estimate (module docstring): (R, t), T_cam_world."""
    heights = np.unique(obs.plate_z)
    if len(heights) < 2:
        raise CalibrationError(f"the spots are all on one plate height ({heights[0]:g} mm); the "
                               "recalibration needs the plate at two heights")
    z1, z2 = heights[0], heights[-1]
    o, v, P = beam_points(beams, obs.cmd, obs.plate_z)
    norm = camera.normalize(obs.uv)
    # camera-frame spots of each plate, from its homography
    p_cam = np.full((len(obs.uv), 3), np.nan)
    poses = {}
    for z in heights:
        sel = obs.plate_z == z
        if sel.sum() < MIN_SPOTS_PER_PLATE:
            raise CalibrationError(f"plate at {z:g} mm: {sel.sum()} spots seen, need at least "
                                   f"{MIN_SPOTS_PER_PLATE}")
        R_i, t_i = _plate_pose(P[sel, :2], z, norm[sel])
        poses[z] = (R_i, t_i)
        p_cam[sel] = P[sel] @ R_i.T + t_i
    # beams seen on both extreme plates: §2.3.1 rotation from their camera-frame segments
    key = [tuple(c) for c in np.round(obs.cmd, 6)]
    on1 = {k: i for i, k in enumerate(key) if obs.plate_z[i] == z1}
    pairs = [(on1[k], i) for i, k in enumerate(key) if obs.plate_z[i] == z2 and k in on1]
    if len(pairs) < 3:
        raise CalibrationError(f"only {len(pairs)} commands seen on both plates "
                               f"({z1:g} and {z2:g} mm), need at least 3")
    i1, i2 = np.array(pairs).T
    w = p_cam[i2] - p_cam[i1]
    vw = P[i2] - P[i1]                     # world segment along each beam
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    vw /= np.linalg.norm(vw, axis=1, keepdims=True)
    R1 = poses[z1][0]
    dR = rotation_between(w @ R1, vw)      # world ≈ dR · R1ᵀ · camera
    R = (dR @ R1.T).T
    # §2.3.2 translation: Σ (I − b bᵀ) t = Σ (I − b bᵀ)(p − R o), b = R v
    b = v @ R.T
    Pm = np.eye(3)[None] - b[:, :, None] * b[:, None, :]
    rhs = p_cam - o @ R.T
    t = np.linalg.solve(Pm.sum(0), np.einsum("nij,nj->i", Pm, rhs))
    return R, t


def spot_residuals(R: np.ndarray, t: np.ndarray, obs: SpotObservations, rays_cam: np.ndarray,
                   o: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(N, 3): each spot (camera ray met with z = z_i) minus its nearest point on its beam."""
    C = -R.T @ t
    d = rays_cam @ R                          # world directions
    X = C + ((obs.plate_z - C[2]) / d[:, 2])[:, None] * d
    r = X - o
    return r - np.einsum("ij,ij->i", r, v)[:, None] * v


def pose_from_spots(obs: SpotObservations, camera: CameraModel, beams: BeamModel
                    ) -> PoseFromSpots:
    """T_cam_world from the spots (module docstring). ``camera``: intrinsics (its pose is not
    used); ``beams``: the head's beam model in the world frame."""
    obs = SpotObservations(obs.cmd, obs.plate_z, obs.uv)
    if not len(obs.uv):
        raise CalibrationError("no spots to estimate the pose from")
    if not np.isfinite(obs.uv).all():
        raise CalibrationError("spot pixels contain NaN or inf")
    R0, t0 = linear_pose(obs, camera, beams)
    o, v, _ = beam_points(beams, obs.cmd, obs.plate_z)
    rays = np.column_stack([camera.normalize(obs.uv), np.ones(len(obs.uv))])

    def fun(x):
        R = cv2.Rodrigues(x[:3])[0]
        return spot_residuals(R, x[3:], obs, rays, o, v).ravel()

    x0 = np.concatenate([cv2.Rodrigues(R0)[0].ravel(), t0])
    sol = least_squares(fun, x0, method="lm", x_scale="jac")
    R, t = cv2.Rodrigues(sol.x[:3])[0], sol.x[3:]
    res = sol.fun.reshape(-1, 3)
    dist = np.linalg.norm(res, axis=1)
    dof = max(2 * len(dist) - 6, 1)          # two independent components per spot
    sigma2 = float(np.sum(dist**2)) / dof
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * sigma2
        std = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        std = np.full(6, np.nan)
    return PoseFromSpots(R, t, dist, float(np.sqrt(np.mean(dist**2))), R0, t0,
                         np.degrees(std[:3]), std[3:])
