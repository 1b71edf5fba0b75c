"""The mirrors alignment check (the paper's (d)): how far the two virtual cameras are turned
against what the rig says, from the target's centres seen by both views.

Vertical disparity. For a pair of matched centres, with the rig's distortion removed and
each view mapped through the rig's own rotations into its parallel camera
(:func:`humanpt.geometry.psvs.parallel_pixels`), eq. (4) wants the two views on one scan
line: ``dv_L (z + b/2 - l)/(z + b/2) = dv_R``. What is left, ``r = v_L - v_R`` (px, in the
right view's scale), is what the rig does not know. A left view turned further (against
the right one) by small angles (w_x, w_y, w_z) rad about the camera's x, y, z gives, with
``x = (u_L - u0)/a_u``, ``y = (v_L - v0)/a_v`` the left view's normalised coordinates::

    r = a_v [ w_x (1 + y^2)  -  w_z x  -  w_y x y ]

a constant part (tilt about x), a part linear in u (roll about z) and a weak saddle (pan
about y: 0.1 px at the image's corner for 0.1 deg). Tilt and roll are fitted by linear
least squares, after the saddle of the pan read from the target's size is removed; a principal point off in v looks exactly like a tilt about x (and is treated like
one: both are removed by turning the mirror or by ``humanpt calibrate psvs``).

The pan shows in depth, not in the vertical disparity: it is read from the target's known
size (:func:`humanpt.calibration.psvs.estimate_psvs` with the rig's baseline held; a
baseline error would be read as a pan).

Thresholds (:func:`thresholds_deg`): the largest turn that keeps the path error under
``budget_mm`` at the working depth z (mm; ``D = z + b/2`` from the virtual centres, b + m
the views' separation ``B``) for a target within ``field_mm`` of the optical axis:

* tilt about x: eq. (4)'s y is the mean of both views' y, so one view tilted by w moves y
  by ``D w / 2``: ``w_x < 2 budget / D`` (0.018 deg at 600 mm);
* roll about z: the left view's u moves by ``a w y``, a disparity error, hence a depth
  error ``D^2/(a B) a w y`` with ``y = field/D``: ``w_z < budget B / (D field)``
  (0.016 deg at 600 mm, 50 mm field);
* pan about y: a disparity offset ``a w``, a depth error ``D^2 w / B``:
  ``w_y < budget B / D^2`` (0.0012 deg at 600 mm: 0.02 px of disparity).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from humanpt.geometry.psvs import eq4_points_mm, parallel_pixels
from humanpt.geometry.rig import DEFAULT_DZ_MM, Rig

from .psvs import CalibrationError, PsvsEstimate, StereoViews, _ideal, estimate_psvs

__all__ = ["Thresholds", "MirrorCheck", "thresholds_deg", "vertical_disparity_px", "check_mirrors",
           "report_lines", "MIN_PAIRS"]

MIN_PAIRS = 6
"""Fewest matched pairs the vertical-disparity fit takes."""


@dataclass(frozen=True)
class Thresholds:
    """The largest turn (deg) of a virtual camera about x (tilt), y (pan), z (roll) that
    keeps the path error under ``budget_mm`` at ``depth_mm`` within ``field_mm`` of the
    axis (module docstring)."""

    budget_mm: float
    depth_mm: float
    field_mm: float
    tilt_x_deg: float
    pan_y_deg: float
    roll_z_deg: float


def thresholds_deg(rig: Rig, budget_mm: float = 0.1, depth_mm: float = DEFAULT_DZ_MM,
                   field_mm: float = 50.0) -> Thresholds:
    """:class:`Thresholds` from the rig's geometry (the formulas in the module docstring)."""
    p = rig.params()
    big_d = depth_mm + p.baseline_mm / 2.0
    sep = p.baseline_mm + p.m_mm
    return Thresholds(budget_mm, depth_mm, field_mm,
                      tilt_x_deg=math.degrees(2.0 * budget_mm / big_d),
                      pan_y_deg=math.degrees(budget_mm * sep / big_d**2),
                      roll_z_deg=math.degrees(budget_mm * sep / (big_d * field_mm)))


def vertical_disparity_px(rig: Rig, uv_right_px: np.ndarray, uv_left_px: np.ndarray) -> np.ndarray:
    """``v_L - v_R`` (...,) px of matched pairs of observed centres (..., 2), in the rig's
    model: distortion removed, each view through the rig's rotation into its parallel
    camera, the left view scaled to the right view's depth (module docstring). Zero for
    a rig that describes the mirrors exactly (and no noise)."""
    params = rig.params()
    uv_r = parallel_pixels(params.right_camera, _ideal(rig, uv_right_px))
    uv_l = parallel_pixels(params.left_camera, _ideal(rig, uv_left_px))
    z = eq4_points_mm(params, _ideal(rig, uv_right_px), _ideal(rig, uv_left_px))[..., 2]
    b, l = params.baseline_mm, params.l_mm
    dv_r = uv_r[..., 1] - params.right_camera.v0
    dv_l = uv_l[..., 1] - params.left_camera.v0
    return dv_l * (z + b / 2.0 - l) / (z + b / 2.0) - dv_r


@dataclass(frozen=True)
class MirrorCheck:
    """The result of :func:`check_mirrors`.

    ``disparity_px`` (M,): v_L - v_R of every pair; ``u_left_px`` (M,): where; ``offset_px``
    (constant part at u = u0), ``slope_px_per_100px`` (its change per 100 px of u);
    ``turn_deg`` (3,) the left view's turn against the right one beyond the rig's, about
    x, y, z (x, z from the vertical disparity; y from the target's size, NaN without an
    estimate), ``sigma_deg`` (3,) their 1-sigma; ``thresholds``; ``passed`` (3,) bool
    (x, y, z within threshold); ``pan_checkable``: whether 2 sigma of the pan is under its
    threshold (else the data cannot check the pan to the path budget)."""

    disparity_px: np.ndarray
    u_left_px: np.ndarray
    offset_px: float
    slope_px_per_100px: float
    turn_deg: np.ndarray
    sigma_deg: np.ndarray
    thresholds: Thresholds
    passed: np.ndarray
    pan_checkable: bool
    n_views: int

    @property
    def ok(self) -> bool:
        return bool(np.all(self.passed))


def check_mirrors(rig: Rig, views: StereoViews, *, budget_mm: float = 0.1, depth_mm: float = DEFAULT_DZ_MM,
                  field_mm: float = 50.0, pan: bool = True) -> MirrorCheck:
    """Check the mirrors against the rig from N views of the target (module docstring).
    ``pan``: also read the pan from the target's size (needs views at several depths; a
    :class:`CalibrationError` from the estimate leaves the pan unchecked). Raises
    :class:`CalibrationError` with fewer than :data:`MIN_PAIRS` pairs."""
    uv_r = views.uv_right_px.reshape(-1, 2)
    uv_l = views.uv_left_px.reshape(-1, 2)
    if len(uv_r) < MIN_PAIRS:
        raise CalibrationError(f"too few matched pairs for the mirrors check: {len(uv_r)} (need {MIN_PAIRS})")
    params = rig.params()
    r = vertical_disparity_px(rig, uv_r, uv_l)
    left = parallel_pixels(params.left_camera, _ideal(rig, uv_l))
    x = (left[:, 0] - params.left_camera.u0) / params.a_u
    y = (left[:, 1] - params.left_camera.v0) / params.a_v
    design = params.a_v * np.stack([1.0 + y**2, -x * y, -x], axis=1)  # w_x, w_y, w_z
    # The pan's saddle is too weak to fit (0.1 px at the corner for 0.1 deg) and would
    # only add its variance to the roll's: it is read from the target's size below, and
    # that pan's (small) saddle is removed from r first.
    cols = [0, 2]
    est: PsvsEstimate | None = None
    if pan:
        try:
            est = estimate_psvs(rig, views, fit_baseline=False)
        except CalibrationError:
            est = None
    pan_rad = 0.0 if est is None else np.radians(est.rotvec_left_deg[1] - rig.psvs.rotvec_left_deg[1])
    r = r - design[:, 1] * pan_rad
    coef, *_ = np.linalg.lstsq(design[:, cols], r, rcond=None)
    resid = r - design[:, cols] @ coef
    dof = max(len(r) - len(cols), 1)
    cov = float(resid @ resid) / dof * np.linalg.inv(design[:, cols].T @ design[:, cols])
    turn = np.full(3, np.nan)
    sigma = np.full(3, np.nan)
    turn[cols] = np.degrees(coef)
    sigma[cols] = np.degrees(np.sqrt(np.diag(cov)))
    if est is not None:
        turn[1] = est.rotvec_left_deg[1] - rig.psvs.rotvec_left_deg[1]
        sigma[1] = est.sigma["rotvec_left_deg_y"]
    th = thresholds_deg(rig, budget_mm, depth_mm, field_mm)
    limit = np.array([th.tilt_x_deg, th.pan_y_deg, th.roll_z_deg])
    passed = np.abs(np.nan_to_num(turn, nan=0.0)) <= limit
    pan_checkable = bool(np.isfinite(sigma[1]) and 2 * sigma[1] <= th.pan_y_deg)
    # the vertical disparity across the image: constant and linear in u parts
    lin = np.stack([np.ones_like(r), (left[:, 0] - params.left_camera.u0) / 100.0], axis=1)
    (offset, slope), *_ = np.linalg.lstsq(lin, r, rcond=None)
    return MirrorCheck(r, uv_l[:, 0], float(offset), float(slope), turn, sigma, th, passed, pan_checkable,
                       len(views))


_AXIS = {0: ("x", "tilt", "its horizontal axis (the camera's x as seen through it)"),
         1: ("y", "pan", "its vertical axis (the camera's y as seen through it)"),
         2: ("z", "roll", "the axis along the view (the camera's z as seen through it)")}


def report_lines(check: MirrorCheck) -> list[str]:
    """What the check found, pass/fail per axis, and which mirror to turn which way."""
    th = check.thresholds
    r = check.disparity_px
    out = [f"mirrors alignment check: {len(r)} pairs from {check.n_views} views",
           f"  vertical disparity v_L - v_R: mean {np.mean(r):+.3f} px, SD {np.std(r):.3f} px, "
           f"range {np.min(r):+.3f} .. {np.max(r):+.3f} px",
           f"  across the image: {check.offset_px:+.3f} px at the centre, {check.slope_px_per_100px:+.4f} px per 100 px of u",
           f"  thresholds (path error < {th.budget_mm} mm at {th.depth_mm:.0f} mm, target within {th.field_mm:.0f} mm "
           f"of the axis): tilt x {th.tilt_x_deg:.4f} deg, pan y {th.pan_y_deg:.4f} deg, roll z {th.roll_z_deg:.4f} deg"]
    limit = (th.tilt_x_deg, th.pan_y_deg, th.roll_z_deg)
    for k in (0, 2, 1):
        axis, what, mirror_axis = _AXIS[k]
        t, s = check.turn_deg[k], check.sigma_deg[k]
        if not np.isfinite(t):
            out.append(f"  {what} about {axis}: not measured (needs the target at several depths)")
            continue
        verdict = "PASS" if check.passed[k] else "FAIL"
        line = f"  left view {what} about {axis}: {t:+.4f} deg +- {s:.4f} (limit {limit[k]:.4f}) {verdict}"
        if k == 1:
            line += " (from the target's size, the rig's baseline assumed right)"
            if not check.pan_checkable:
                line += (f"; the data check the pan to +-{2 * s:.4f} deg (2 sigma) only, not to {limit[k]:.4f}: "
                         f"calibrate psvs and judge the path")
        out.append(line)
        if not check.passed[k]:
            out.append(f"    -> turn the left outer mirror about {mirror_axis} by {-t / 2:+.4f} deg "
                       f"(half the view's turn; or the right one by {t / 2:+.4f} deg), "
                       f"or run `humanpt calibrate psvs` to teach the rig this turn")
    out.append("  mirrors " + ("PASS" if check.ok else "FAIL") + " (the turns are of the left view against the "
               "right one beyond what the rig says)")
    return out
