"""The servo laws of the controller: pure functions of transforms (metres, radians).

Both laws return a per-cycle flange step in the WORLD frame, about the flange origin:
``(d_translation_m (3,), d_rotation_rad (3,) rotation vector)``, saturated to the speed
limits.  The robot applies it as :func:`humanpt.geometry.transforms.apply_step` does
(``R' = exp(d_rot) R``, ``t' = t + d_t``).

* ``paper_step``: Section 5 of the paper.  X_FG and X_FD are the six-vectors (mm, deg,
  yaw-pitch-roll Z-Y-X) of the TOB frame G and the desired frame D in the flange frame;
  E_F = X_FG - X_FD (angles wrapped); the flange screw V_F = K E_F, the three angle
  errors taken as a small-rotation vector [43] (valid for small changes per cycle).
  The paper prints V_F = -K E_F: with E_F = X_FG - X_FD the flange must move *towards*
  G, so the sign that converges is +K; we keep the paper's E_F and K.
* ``thetau_step`` (default): the flange pose that puts D on G is
  ``world_T_fd = world_T_tob @ inv(flange_T_D)``; the error is its translation and its
  rotation as theta-u (a rotation vector: no Euler singularity); feed-forward of the
  target's velocity removes the lag proportional to speed over gain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humanpt.geometry.transforms import (
    apply_step,
    invert_transform,
    rotvec_from_matrix,
    x_from_transform,
)


def norm3(v: np.ndarray) -> float:
    """|v| of a 3-vector, as a float."""
    return float(np.linalg.norm(v))


@dataclass(frozen=True)
class Step:
    d_translation_m: np.ndarray  # (3,) world frame
    d_rotation_rad: np.ndarray  # (3,) rotation vector, world frame, about the flange origin
    saturated: bool
    error_translation_m: float  # |G - D| (m)
    error_rotation_rad: float  # angle between the TOB frame and D's (rad)


def saturate(
    d_t: np.ndarray, d_r: np.ndarray, max_step_m: float, max_step_rad: float
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Scale a step down to the per-cycle limits (by norm, keeping its direction)."""
    sat = False
    nt, nr = norm3(d_t), norm3(d_r)
    if nt > max_step_m:
        d_t, sat = d_t * (max_step_m / nt), True
    if nr > max_step_rad:
        d_r, sat = d_r * (max_step_rad / nr), True
    return d_t, d_r, sat


def extrapolate(
    world_T_tob: np.ndarray, v_m_s: np.ndarray, w_rad_s: np.ndarray, dt_s: float
) -> np.ndarray:
    """A pose moved at constant (world-frame) velocity for ``dt_s`` (may be negative)."""
    return apply_step(world_T_tob, np.asarray(v_m_s) * dt_s, np.asarray(w_rad_s) * dt_s)


def desired_flange(world_T_tob: np.ndarray, flange_T_desired: np.ndarray) -> np.ndarray:
    """The flange pose at which the desired frame D coincides with G."""
    return world_T_tob @ invert_transform(flange_T_desired)


def pose_error(
    world_T_flange: np.ndarray, world_T_target: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(translation error (3,) m, theta-u rotation error (3,) rad), world frame."""
    e_t = world_T_target[:3, 3] - world_T_flange[:3, 3]
    e_r = rotvec_from_matrix(world_T_target[:3, :3] @ world_T_flange[:3, :3].T, assume_valid=True)
    return e_t, e_r


def thetau_step(
    world_T_flange: np.ndarray,
    world_T_tob: np.ndarray,
    flange_T_desired: np.ndarray,
    *,
    v_tob_m_s: np.ndarray,
    w_tob_rad_s: np.ndarray,
    k_t: float,
    k_r: float,
    dt_s: float,
    max_step_m: float,
    max_step_rad: float,
    feed_forward: bool = True,
    position_only: bool = False,
    deadband_m: float = 0.0,
    deadband_rad: float = 0.0,
    still_m_s: float = 0.0,
    still_rad_s: float = 0.0,
) -> Step:
    """Default law; with ``position_only`` only the translation of D towards G is servoed."""
    world_T_fd = desired_flange(world_T_tob, flange_T_desired)
    e_t, e_r = pose_error(world_T_flange, world_T_fd)
    v = k_t * e_t
    w = k_r * e_r
    if feed_forward:
        # The desired flange pose moves rigidly with the target.
        v = v + v_tob_m_s + np.cross(w_tob_rad_s, world_T_fd[:3, 3] - world_T_tob[:3, 3])
        w = w + w_tob_rad_s
    if position_only:
        # Keep the orientation; move so that D (not the flange origin) goes to G.
        world_p_d = (world_T_flange @ flange_T_desired)[:3, 3]
        v = k_t * (world_T_tob[:3, 3] - world_p_d) + (v_tob_m_s if feed_forward else 0.0)
        w = np.zeros(3)
        e_r = np.zeros(3)
    # Report the error as the paper sees it: where D is with respect to G.
    world_p_d = (world_T_flange @ flange_T_desired)[:3, 3]
    e_gd = norm3(world_T_tob[:3, 3] - world_p_d)
    # Deadbands: each part is left alone while its error is small and the target still.
    if norm3(e_r) < deadband_rad and norm3(w_tob_rad_s) < still_rad_s:
        w = np.zeros(3)
        v = k_t * (world_T_tob[:3, 3] - world_p_d) + (v_tob_m_s if feed_forward else 0.0)
    if e_gd < deadband_m and norm3(v_tob_m_s) < still_m_s and not np.any(w):
        v = np.zeros(3)
    d_t, d_r, sat = saturate(v * dt_s, w * dt_s, max_step_m, max_step_rad)
    return Step(d_t, d_r, sat, e_gd, norm3(e_r))


def paper_step(
    world_T_flange: np.ndarray,
    world_T_tob: np.ndarray,
    flange_T_desired: np.ndarray,
    *,
    k_t: float,
    k_r: float,
    dt_s: float,
    max_step_m: float,
    max_step_rad: float,
    position_only: bool = False,
) -> Step:
    """Section 5's law V_F = K E_F with E_F = X_FG - X_FD in the flange frame."""
    flange_T_tob = invert_transform(world_T_flange) @ world_T_tob
    x_fg = x_from_transform(_mm(flange_T_tob))
    x_fd = x_from_transform(_mm(flange_T_desired))
    e = x_fg - x_fd
    e[3:] = (e[3:] + 180.0) % 360.0 - 180.0  # wrap the angle errors
    if position_only:
        e[3:] = 0.0
    v_flange_m_s = k_t * e[:3] * 1e-3
    # (d psi, d theta, d phi) about (z, y, x) as a small rotation vector (x, y, z) [43].
    w_flange_rad_s = k_r * np.radians(e[[5, 4, 3]])
    R = world_T_flange[:3, :3]
    d_t, d_r, sat = saturate(
        R @ v_flange_m_s * dt_s, R @ w_flange_rad_s * dt_s, max_step_m, max_step_rad
    )
    return Step(
        d_t, d_r, sat, float(np.linalg.norm(e[:3])) * 1e-3, float(np.linalg.norm(np.radians(e[3:])))
    )


def _mm(T_m: np.ndarray) -> np.ndarray:
    T = np.array(T_m, dtype=float)
    T[:3, 3] *= 1e3
    return T
