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

K: two scalar gains (``k_t`` 1/s on the translation, ``k_r`` on the rotation: the default
diagonal), or the paper's 6x6 weight matrix ``K`` (flange frame: rows and columns (x, y, z,
rx, ry, rz), the error a translation in m and a small rotation vector in rad), which both
laws accept (:func:`gain`); with ``K`` given the scalars are not used.

When the demanded flange motion exceeds the limits, ``saturation`` chooses what gives:
``scale`` shrinks the whole step (translation and rotation each by norm: the flange falls
behind the target, G drifts out of the image), ``position_first`` (default) keeps the
desired point D on G - G at the image centre and at its depth - and lets the part of the
rotation that would swing D lag (:func:`position_first`).
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
from humanpt.geometry.units import to_mm


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
    # The fraction of the demanded rotation that swings D (its part across the line from the
    # flange to D) actually commanded: < 1 when position_first let the orientation lag.
    rotation_scale: float = 1.0
    position_first: bool = False  # made by position_first (not by the scaled thetau law)


def gain(k_t: float, k_r: float, K: np.ndarray | None, world_R_flange: np.ndarray,
         e_t: np.ndarray, e_r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(v (3,), w (3,)) = K (e_t, e_r): world-frame errors (m, rad) to world-frame velocities
    (m/s, rad/s).  Without ``K`` the two scalar gains (bit for bit the old law); with it the
    6x6 matrix in the flange frame: ``R K (R^T e_t, R^T e_r)``."""
    if K is None:
        return k_t * e_t, k_r * e_r
    R = np.asarray(world_R_flange, dtype=float)
    u = K @ np.concatenate([R.T @ e_t, R.T @ e_r])
    return R @ u[:3], R @ u[3:]


def saturate(
    d_t: np.ndarray, d_r: np.ndarray, max_step_m: float, max_step_rad: float, together: bool = False
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Scale a step down to the per-cycle limits (by norm, keeping its direction): each
    part by its own factor, or with ``together`` both by the smaller (the step's screw
    kept: a point carried by the flange, e.g. a tool's tip, moves along the same line,
    only less far)."""
    nt, nr = norm3(d_t), norm3(d_r)
    kt = max_step_m / nt if nt > max_step_m else 1.0
    kr = max_step_rad / nr if nr > max_step_rad else 1.0
    if together:
        kt = kr = min(kt, kr)
    return d_t * kt if kt < 1.0 else d_t, d_r * kr if kr < 1.0 else d_r, kt < 1.0 or kr < 1.0


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


SATURATIONS = ("position_first", "scale")


def position_first(
    world_T_flange: np.ndarray,
    flange_T_desired: np.ndarray,
    v_d_m_s: np.ndarray,
    w_rad_s: np.ndarray,
    dt_s: float,
    max_step_m: float,
    max_step_rad: float,
) -> tuple[np.ndarray, np.ndarray, bool, float]:
    """The flange step (world frame, about the flange origin) that moves D at ``v_d_m_s``
    (3,) and turns the flange at ``w_rad_s`` (3,) as far as the per-cycle limits allow,
    D's motion first: ``(d_translation_m, d_rotation_rad, saturated, rotation_scale)``.

    The flange turning at w swings D (at r = D - flange origin) by w x r, so the flange must
    translate by v_D - w x r. The rotation about the line flange-D (w's part along r) costs
    no translation and is kept (limited to ``max_step_rad`` with the rest); the part across
    it is scaled by the largest s in [0, 1] that keeps the translation within
    ``max_step_m``: the orientation lags, D stays on G. When D's motion alone exceeds the
    limit it is scaled down and nothing swings D (s = 0). The step is exact for the robot's
    ``R' = exp(d_rot) R, t' = t + d_t``: D moves by ``v_D dt`` (s is found to first order,
    then bisected down if the exact swing needs more translation than the limit)."""
    v_d, w = np.asarray(v_d_m_s, dtype=float), np.asarray(w_rad_s, dtype=float)
    v_max, w_max = max_step_m / dt_s, max_step_rad / dt_s
    sat = False
    nw = norm3(w)
    if nw > w_max:
        w, sat = w * (w_max / nw), True
    r = (world_T_flange @ flange_T_desired)[:3, 3] - world_T_flange[:3, 3]
    u = r / norm3(r)
    w_par = float(w @ u) * u
    w_perp = w - w_par
    c = -np.cross(w_perp, r)  # the flange velocity that cancels the swing of D by w_perp
    nv = norm3(v_d)
    if nv > v_max:
        v_d, s, sat = v_d * (v_max / nv), 0.0, True
    else:
        cc, vc = float(c @ c), float(v_d @ c)
        # largest s with |v_d + s c| <= v_max (s = 0 satisfies it)
        s = 1.0 if cc == 0.0 else min(1.0, (-vc + np.sqrt(max(vc * vc - cc * (nv * nv - v_max * v_max), 0.0))) / cc)
        sat = sat or s < 1.0

    def step(s: float) -> tuple[np.ndarray, np.ndarray]:
        d_r = (w_par + s * w_perp) * dt_s
        # D moves by d_t + (exp(d_r) - I) r: choose d_t so that it moves by v_d dt exactly.
        return v_d * dt_s - (apply_step(np.eye(4), np.zeros(3), d_r)[:3, :3] - np.eye(3)) @ r, d_r

    d_t, d_r = step(s)
    if norm3(d_t) > max_step_m * (1 + 1e-12):
        # s came from the first-order swing; the exact one is a little larger: bisect s
        # (s = 0 is feasible: the rotation about the flange-D line does not move D).
        lo, hi = 0.0, s
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if norm3(step(mid)[0]) <= max_step_m else (lo, mid)
        s, sat = lo, True
        d_t, d_r = step(s)
    return d_t, d_r, sat, s


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
    saturation: str = "scale",
    position_first_beyond_m: float = 0.0,
    engaged: bool = False,
    K: np.ndarray | None = None,
) -> Step:
    """Default law; with ``position_only`` only the translation of D towards G is servoed.
    ``saturation``: ``scale`` (the flange's pose servoed, the step shrunk by norm to the
    limits) or ``position_first`` (the same while within the limits, or while |G - D| is
    within ``position_first_beyond_m``; a step beyond the limits with G farther from D is
    replaced by D servoed onto G, the flange turning about D and the orientation lagging:
    :func:`position_first`). ``engaged``: the previous step was position_first's; it
    stays so while the limits bind, whatever |G - D| (hysteresis: no chatter at the band).
    ``K``: the 6x6 gain matrix (flange frame) instead of ``k_t``, ``k_r`` (:func:`gain`)."""
    if saturation not in SATURATIONS:
        raise ValueError(f"saturation must be one of {SATURATIONS}, got {saturation!r}")
    step = _scale_step(world_T_flange, world_T_tob, flange_T_desired, v_tob_m_s, w_tob_rad_s, k_t, k_r, dt_s,
                       max_step_m, max_step_rad, feed_forward, position_only, deadband_m, deadband_rad, still_m_s,
                       still_rad_s, K)
    if saturation == "position_first" and step.saturated and (engaged or step.error_translation_m
                                                              > position_first_beyond_m):
        # Within the limits both agree on where to go; beyond them, once G has fallen away
        # from D, D's motion comes first. (Within the band the orientation keeps its
        # priority: a noisy orientation, e.g. the paper's perception, saturates the old
        # law now and then by the 0.7 m lever; letting it lag biases that perception.)
        return _position_first_step(world_T_flange, world_T_tob, flange_T_desired, v_tob_m_s, w_tob_rad_s,
                                    k_t, k_r, dt_s, max_step_m, max_step_rad, feed_forward, position_only,
                                    deadband_m, deadband_rad, still_m_s, still_rad_s, K)
    return step


def _scale_step(world_T_flange, world_T_tob, flange_T_desired, v_tob_m_s, w_tob_rad_s, k_t, k_r, dt_s,
                max_step_m, max_step_rad, feed_forward, position_only, deadband_m, deadband_rad, still_m_s,
                still_rad_s, K=None) -> Step:
    """The thetau law, its step scaled by norm to the limits (``saturation = "scale"``)."""
    world_T_fd = desired_flange(world_T_tob, flange_T_desired)
    e_t, e_r = pose_error(world_T_flange, world_T_fd)
    R = world_T_flange[:3, :3]
    v, w = gain(k_t, k_r, K, R, e_t, e_r)
    if feed_forward:
        # The desired flange pose moves rigidly with the target.
        v = v + v_tob_m_s + np.cross(w_tob_rad_s, world_T_fd[:3, 3] - world_T_tob[:3, 3])
        w = w + w_tob_rad_s
    if position_only:
        # Keep the orientation; move so that D (not the flange origin) goes to G.
        world_p_d = (world_T_flange @ flange_T_desired)[:3, 3]
        v = gain(k_t, k_r, K, R, world_T_tob[:3, 3] - world_p_d, np.zeros(3))[0] + (v_tob_m_s if feed_forward else 0.0)
        w = np.zeros(3)
        e_r = np.zeros(3)
    # Report the error as the paper sees it: where D is with respect to G.
    world_p_d = (world_T_flange @ flange_T_desired)[:3, 3]
    e_gd = norm3(world_T_tob[:3, 3] - world_p_d)
    # Deadbands: each part is left alone while its error is small and the target still.
    if norm3(e_r) < deadband_rad and norm3(w_tob_rad_s) < still_rad_s:
        w = np.zeros(3)
        v = gain(k_t, k_r, K, R, world_T_tob[:3, 3] - world_p_d, np.zeros(3))[0] + (v_tob_m_s if feed_forward else 0.0)
    if e_gd < deadband_m and norm3(v_tob_m_s) < still_m_s and not np.any(w):
        v = np.zeros(3)
    d_t, d_r, sat = saturate(v * dt_s, w * dt_s, max_step_m, max_step_rad)
    return Step(d_t, d_r, sat, e_gd, norm3(e_r))


def _position_first_step(world_T_flange, world_T_tob, flange_T_desired, v_tob, w_tob, k_t, k_r, dt_s,
                         max_step_m, max_step_rad, feed_forward, position_only, deadband_m, deadband_rad,
                         still_m_s, still_rad_s, K=None) -> Step:
    """The thetau law with D, not the flange origin, servoed onto G: D's velocity
    ``k_t (G - D) + v_G`` and the rotation ``k_r theta-u + w_G`` (both feed-forwards),
    combined by :func:`position_first`: G held at the image centre while the orientation
    catches up."""
    world_T_fd = desired_flange(world_T_tob, flange_T_desired)
    _, e_r = pose_error(world_T_flange, world_T_fd)
    world_p_d = (world_T_flange @ flange_T_desired)[:3, 3]
    e_gd = world_T_tob[:3, 3] - world_p_d
    if position_only:
        e_r = np.zeros(3)
    v_d, w = gain(k_t, k_r, K, world_T_flange[:3, :3], e_gd, e_r)
    v_d = v_d + (v_tob if feed_forward else 0.0)
    w = w + (w_tob if feed_forward else 0.0)
    if position_only:
        w, e_r = np.zeros(3), np.zeros(3)
    # Deadbands (as ``scale``): each part is left alone while its error is small and the
    # target still.
    if norm3(e_r) < deadband_rad and norm3(w_tob) < still_rad_s:
        w = np.zeros(3)
    if norm3(e_gd) < deadband_m and norm3(v_tob) < still_m_s and not np.any(w):
        v_d = np.zeros(3)
    d_t, d_r, sat, s = position_first(world_T_flange, flange_T_desired, v_d, w, dt_s, max_step_m, max_step_rad)
    return Step(d_t, d_r, sat, norm3(e_gd), norm3(e_r), s, True)


def fov_margin_px(params, camera_T_tob_mm: np.ndarray, tob_p_sources_mm: np.ndarray) -> float:
    """How far inside the complex image the target's sources are: the smallest distance (px)
    of their six images (three sources (3, 3) mm in the TOB frame, two views; the PSVS
    model ``params``, :func:`humanpt.geometry.psvs.project`, distortion included) to the
    image border (pixel centres at integers, the image spans [-0.5, size - 0.5]); negative
    when one is outside; -10000 when one is behind a view's centre."""
    from humanpt.geometry.errors import GeometryError
    from humanpt.geometry.psvs import project

    T = np.asarray(camera_T_tob_mm, dtype=float)
    camera_p = np.asarray(tob_p_sources_mm, dtype=float) @ T[:3, :3].T + T[:3, 3]
    try:
        uv = np.concatenate(project(params, camera_p))
    except GeometryError:
        return FOV_BEHIND_PX
    w, h = params.image_size_px
    d = np.minimum(np.minimum(uv[:, 0] + 0.5, w - 0.5 - uv[:, 0]), np.minimum(uv[:, 1] + 0.5, h - 0.5 - uv[:, 1]))
    return float(max(d.min(), FOV_BEHIND_PX))


FOV_BEHIND_PX = -10000.0


def image_offset_px(params, camera_p_g_mm: np.ndarray, camera_p_d_mm: np.ndarray) -> float:
    """How far (px) G's image is from where G at D would appear, the larger of the two views
    (ideal pixels, :func:`humanpt.geometry.psvs.project`); 10000 when G is behind a view."""
    from humanpt.geometry.errors import GeometryError
    from humanpt.geometry.psvs import project

    try:
        g_r, g_l = project(params, np.asarray(camera_p_g_mm, dtype=float), distort=False)
        d_r, d_l = project(params, np.asarray(camera_p_d_mm, dtype=float), distort=False)
    except GeometryError:
        return -FOV_BEHIND_PX
    return float(min(max(np.linalg.norm(g_r - d_r), np.linalg.norm(g_l - d_l)), -FOV_BEHIND_PX))


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
    K: np.ndarray | None = None,
) -> Step:
    """Section 5's law V_F = K E_F with E_F = X_FG - X_FD in the flange frame; K the two
    scalar gains, or the 6x6 matrix ``K`` on (x, y, z in m; the angle errors as a small
    rotation vector (rx, ry, rz) = (d phi, d theta, d psi) in rad)."""
    flange_T_tob = invert_transform(world_T_flange) @ world_T_tob
    x_fg = x_from_transform(to_mm(flange_T_tob))
    x_fd = x_from_transform(to_mm(flange_T_desired))
    e = x_fg - x_fd
    e[3:] = (e[3:] + 180.0) % 360.0 - 180.0  # wrap the angle errors
    if position_only:
        e[3:] = 0.0
    # (d psi, d theta, d phi) about (z, y, x) as a small rotation vector (x, y, z) [43].
    if K is None:
        v_flange_m_s = k_t * e[:3] * 1e-3
        w_flange_rad_s = k_r * np.radians(e[[5, 4, 3]])
    else:
        u = K @ np.concatenate([e[:3] * 1e-3, np.radians(e[[5, 4, 3]])])
        v_flange_m_s, w_flange_rad_s = u[:3], u[3:]
    R = world_T_flange[:3, :3]
    d_t, d_r, sat = saturate(
        R @ v_flange_m_s * dt_s, R @ w_flange_rad_s * dt_s, max_step_m, max_step_rad
    )
    return Step(
        d_t, d_r, sat, float(np.linalg.norm(e[:3])) * 1e-3, float(np.linalg.norm(np.radians(e[3:])))
    )

