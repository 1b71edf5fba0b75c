"""Stereo error model: first-order propagation of image-coordinate noise.

The paper reports the precision of the recorded state vector X as standard deviations
(Table 1). This module predicts them: the observed complex-image coordinates of each source,
``(u_R, v_R, u_L, v_L)``, carry independent noise of standard deviation ``sigma_px``; the
Jacobian J of the whole measurement chain (undistortion, triangulation by eq. (4)/(2)/least
squares, eq. (7), (8), the frame change and the Z-Y-X angles) at the noise-free
observations maps it to ``cov = J diag(sigma^2) J^T``. J is taken by central differences
(step 1e-3 px) of the very functions the pipeline uses, so the model cannot drift from the
implementation. :func:`monte_carlo_pose_x` samples the same chain for checking the model.

Units: 3D in mm, angles in degrees, image noise in px.
"""

from __future__ import annotations

import numpy as np

from .psvs import PsvsParams, project, triangulate
from .target import TargetModel, tob_frame_from_points
from .transforms import compose, transform_points, x_from_transform

__all__ = [
    "point_covariance_mm2",
    "point_sigma_mm",
    "pose_covariance",
    "pose_sigma",
    "monte_carlo_pose_x",
    "wrap_angle_deg",
]

_STEP_PX = 1e-3


def wrap_angle_deg(angle_deg: np.ndarray) -> np.ndarray:
    """Wrap angles (any shape) into [-180, 180) degrees."""
    return (np.asarray(angle_deg, dtype=float) + 180.0) % 360.0 - 180.0


def _sigma_vector(sigma_px, n: int) -> np.ndarray:
    s = np.broadcast_to(np.asarray(sigma_px, dtype=float), (n,)).copy()
    if np.any(~np.isfinite(s)) or np.any(s < 0):
        raise ValueError(f"sigma_px must be finite and >= 0, got {sigma_px!r}")
    return s


def _jacobian(func, x0: np.ndarray, angle_mask: np.ndarray | None = None) -> np.ndarray:
    """Central-difference Jacobian of func: R^n -> R^m at x0, all n columns evaluated in one
    vectorised call. Angular outputs (mask) are differenced modulo 360 deg."""
    n = x0.size
    steps = np.eye(n) * _STEP_PX
    plus = func(x0[None, :] + steps)
    minus = func(x0[None, :] - steps)
    diff = plus - minus
    if angle_mask is not None:
        diff[:, angle_mask] = wrap_angle_deg(diff[:, angle_mask])
    return (diff / (2.0 * _STEP_PX)).T


def point_covariance_mm2(
    params: PsvsParams, camera_p_mm, sigma_px, method: str = "eq4"
) -> np.ndarray:
    """Predicted covariance (3, 3), mm^2, of a point triangulated by ``method`` from its
    observed (distorted) right and left pixels, each of ``u_R, v_R, u_L, v_L`` having
    standard deviation ``sigma_px`` (scalar or 4 values). ``camera_p_mm`` (3,), camera
    frame."""
    p = np.asarray(camera_p_mm, dtype=float).reshape(3)
    uv_r, uv_l = project(params, p)
    obs = np.concatenate([uv_r, uv_l])
    s = _sigma_vector(sigma_px, 4)

    def f(o):
        return triangulate(params, o[:, :2], o[:, 2:], method=method)

    jac = _jacobian(f, obs)
    return jac @ np.diag(s**2) @ jac.T


def point_sigma_mm(params: PsvsParams, camera_p_mm, sigma_px, method: str = "eq4") -> np.ndarray:
    """Predicted standard deviations (3,) of x, y, z (mm) - see
    :func:`point_covariance_mm2`."""
    return np.sqrt(np.diag(point_covariance_mm2(params, camera_p_mm, sigma_px, method)))


def _pose_chain(params, model, a_T_camera, tob_T_frame, method):
    def f(obs):  # obs (k, 12): per source A, B, C: u_R, v_R, u_L, v_L
        o = obs.reshape(-1, 3, 4)
        pts = triangulate(params, o[..., :2], o[..., 2:], method=method)  # (k, 3, 3)
        camera_T_tob = tob_frame_from_points(pts[:, 0], pts[:, 1], pts[:, 2])
        return x_from_transform(compose(a_T_camera, camera_T_tob, tob_T_frame))

    return f


def _observations(params, model, camera_T_tob) -> np.ndarray:
    camera_p = transform_points(camera_T_tob, model.source_positions_mm)  # (3, 3)
    uv_r, uv_l = project(params, camera_p)
    return np.concatenate([uv_r, uv_l], axis=-1).reshape(12)


def pose_covariance(
    params: PsvsParams,
    model: TargetModel,
    camera_T_tob: np.ndarray,
    sigma_px,
    method: str = "eq4",
    a_T_camera: np.ndarray | None = None,
    tob_T_frame: np.ndarray | None = None,
) -> np.ndarray:
    """Predicted covariance (6, 6) of the six-vector X = (x, y, z [mm], psi, theta, phi
    [deg]) of the TOB measured by the PSVS at the true pose ``camera_T_tob`` (4, 4).

    Each of the 12 observed coordinates (u_R, v_R, u_L, v_L of A, B, C) has standard
    deviation ``sigma_px`` (scalar or 12 values). ``a_T_camera`` expresses X in another
    frame (e.g. ``world_T_camera = world_T_flange @ flange_T_camera``; default: camera
    frame). ``tob_T_frame`` (default identity) gives X of a frame fixed to the TOB instead of
    G, e.g. ``model.tob_T_tip`` for the driver tip P (eq. (9)). Labels are taken as known.
    """
    a_T_camera = np.eye(4) if a_T_camera is None else np.asarray(a_T_camera, float)
    tob_T_frame = np.eye(4) if tob_T_frame is None else np.asarray(tob_T_frame, float)
    obs = _observations(params, model, np.asarray(camera_T_tob, float))
    s = _sigma_vector(sigma_px, 12)
    mask = np.array([False, False, False, True, True, True])
    jac = _jacobian(_pose_chain(params, model, a_T_camera, tob_T_frame, method), obs, mask)
    return jac @ np.diag(s**2) @ jac.T


def pose_sigma(
    params: PsvsParams,
    model: TargetModel,
    camera_T_tob: np.ndarray,
    sigma_px,
    method: str = "eq4",
    a_T_camera: np.ndarray | None = None,
    tob_T_frame: np.ndarray | None = None,
) -> np.ndarray:
    """Predicted standard deviations (6,) of X = (x, y, z [mm], psi, theta, phi [deg]) -
    see :func:`pose_covariance`."""
    cov = pose_covariance(params, model, camera_T_tob, sigma_px, method, a_T_camera, tob_T_frame)
    return np.sqrt(np.diag(cov))


def monte_carlo_pose_x(
    params: PsvsParams,
    model: TargetModel,
    camera_T_tob: np.ndarray,
    sigma_px,
    n_samples: int,
    rng: np.random.Generator,
    method: str = "eq4",
    a_T_camera: np.ndarray | None = None,
    tob_T_frame: np.ndarray | None = None,
) -> np.ndarray:
    """Monte Carlo counterpart of :func:`pose_covariance`: ``n_samples`` six-vectors X
    (n_samples, 6) measured from observations perturbed by Gaussian noise of
    ``sigma_px`` drawn from the caller's seeded ``rng``."""
    a_T_camera = np.eye(4) if a_T_camera is None else np.asarray(a_T_camera, float)
    tob_T_frame = np.eye(4) if tob_T_frame is None else np.asarray(tob_T_frame, float)
    obs = _observations(params, model, np.asarray(camera_T_tob, float))
    s = _sigma_vector(sigma_px, 12)
    noisy = obs[None, :] + rng.standard_normal((int(n_samples), 12)) * s
    return _pose_chain(params, model, a_T_camera, tob_T_frame, method)(noisy)
