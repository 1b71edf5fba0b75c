"""Hand-eye calibration AX = YB (the paper's (c), citing Zhuang, Roth and Sudhakar 1994).

The robot holds the PSVS on its flange and looks at a target fixed in the world from N
poses. Pose i gives ``A_i = world_T_flange_i`` (the robot's state) and the PSVS's
measurement ``camera_T_target_i`` (averaged while still); the unknowns are ``X =
flange_T_camera`` (the hand-eye transform the rig stores) and ``Y = world_T_target``.
With ``B_i = target_T_camera_i`` (the measurement inverted)::

    A_i X = Y B_i        (world_T_flange @ flange_T_camera = world_T_target @ target_T_camera)

:func:`solve_ax_yb` solves it in two steps: a closed-form start (Shah 2013: the rotations
from the null space of ``[R_B_i (x) R_A_i, -I9]`` by SVD, each projected onto SO(3), then
the translations by linear least squares), then nonlinear least squares
(``scipy.optimize.least_squares``) on each pose's rotation and translation residual of
``B_i`` against ``inv(X) inv(A_i) Y``, each camera axis weighted by its own spread. The
1-sigma of X is the larger of the Gauss-Newton covariance (scaled by the residuals) and
the jackknife's (leave one pose out; from 4 poses). When the installed
OpenCV has them (4.x; 5.0 does not export them) ``cv2.calibrateRobotWorldHandEye``
(AX = ZB) and ``cv2.calibrateHandEye`` (AX = XB on relative motions) cross-check X.

:func:`plan_poses` plans where the robot should go: tilts of the camera about the target
(two axes), turns about the optical axis and distance changes, so that the target stays
on the optical axis and the motion is not degenerate.

Units: mm and degrees outside, (4, 4) ``a_T_b`` transforms, stacks (N, 4, 4).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from humanpt.geometry.puma import (
    HOME_JOINTS_DEG,
    PumaKinematics,
    RobotModelConfig,
    UnreachableError,
)
from humanpt.geometry.rig import Calibration, HandEye, Rig
from humanpt.geometry.transforms import (
    check_rigid,
    interpolate_transform,
    invert_transform,
    make_transform,
    matrix_from_rotvec,
    rotation_angle_rad,
    rotvec_from_matrix,
    transform_from_x,
    x_from_transform,
)

__all__ = ["HandEyeError", "HandEyeResult", "solve_ax_yb", "closed_form_ax_yb", "check_motion",
           "opencv_cross_check", "apply_to_rig", "plan_poses", "puma_move_check", "METHOD"]

METHOD = "ax=yb"
"""The rig's ``hand_eye.calibration.method`` this tool writes."""

MIN_POSES = 3


class HandEyeError(ValueError):
    """Input the solver cannot use: too few poses, degenerate motion, bad transforms. The
    message says what and why, in one line."""


@dataclass(frozen=True)
class HandEyeResult:
    """An AX = YB solution.

    ``flange_T_camera_mm`` (4, 4): X, mm. ``world_T_target_mm`` (4, 4): Y, mm.
    ``flange_T_camera_sigma`` (6,): 1-sigma of X as (x, y, z mm, yaw, pitch, roll deg).
    ``residual_mm`` (N,), ``residual_deg`` (N,): per pose, how far the measured target
    (camera frame) is from where X and Y put it (translation mm, rotation angle deg).
    ``used`` (N,) bool: poses in the fit (False: rejected as an outlier).
    ``closed_form_flange_T_camera_mm``: the closed-form start. ``cross_check``: {name:
    (4, 4) X} from OpenCV's solvers, empty when the installed OpenCV lacks them
    (``cross_check_note`` says so)."""

    flange_T_camera_mm: np.ndarray
    world_T_target_mm: np.ndarray
    flange_T_camera_sigma: np.ndarray
    residual_mm: np.ndarray
    residual_deg: np.ndarray
    used: np.ndarray
    closed_form_flange_T_camera_mm: np.ndarray
    cross_check: dict[str, np.ndarray] = field(default_factory=dict)
    cross_check_note: str = ""
    # The camera-to-robot time offset (humanpt.calibration.timing.TimeOffset) measured from
    # the same run's moves, when the caller measured it; written to the rig's [timing].
    time_offset: object | None = None

    @property
    def n_poses(self) -> int:
        return int(np.sum(self.used))

    @property
    def flange_T_camera_x(self) -> np.ndarray:
        """X as (x, y, z mm, yaw, pitch, roll deg), the rig's ``flange_T_camera_x``."""
        return x_from_transform(self.flange_T_camera_mm)

    def summary_lines(self) -> list[str]:
        """The report: per-pose residuals, their spread, the estimate with its 1-sigma and
        the OpenCV cross-check."""
        lines = [f"hand-eye AX = YB from {self.n_poses} poses ({len(self.used) - self.n_poses} rejected)",
                 "  pose  residual mm  residual deg"]
        for i, (e_mm, e_deg, ok) in enumerate(zip(self.residual_mm, self.residual_deg, self.used, strict=True)):
            lines.append(f"  {i:4d}  {e_mm:11.4f}  {e_deg:12.4f}" + ("" if ok else "  (rejected)"))
        u = self.used
        lines.append(f"  spread: translation RMS {_rms(self.residual_mm[u]):.4f} mm, max {self.residual_mm[u].max():.4f} mm; "
                     f"rotation RMS {_rms(self.residual_deg[u]):.4f} deg, max {self.residual_deg[u].max():.4f} deg")
        x, s = self.flange_T_camera_x, self.flange_T_camera_sigma
        names = ("x mm", "y mm", "z mm", "yaw deg", "pitch deg", "roll deg")
        lines.append("  flange_T_camera (X): " + ", ".join(f"{n[:-4] if n.endswith('deg') else n[:-3]} = "
                                                            f"{v:.4f} +- {e:.4f} {n.split()[1]}"
                                                            for n, v, e in zip(names, x, s, strict=True)))
        if self.cross_check:
            for name, T in self.cross_check.items():
                dt, da = pose_difference(T, self.flange_T_camera_mm)
                lines.append(f"  cross-check {name}: differs by {dt:.4f} mm, {da:.4f} deg")
        if self.cross_check_note:
            lines.append(f"  cross-check: {self.cross_check_note}")
        return lines


def _rms(v: np.ndarray) -> float:
    v = np.asarray(v, dtype=float)
    return float(np.sqrt(np.mean(v**2))) if v.size else 0.0


def pose_difference(a_T_b: np.ndarray, a_T_c: np.ndarray) -> tuple[float, float]:
    """(translation mm, rotation deg) between two poses of the same frame."""
    d = invert_transform(a_T_b) @ a_T_c
    return float(np.linalg.norm(a_T_b[:3, 3] - a_T_c[:3, 3])), float(np.degrees(rotation_angle_rad(d[:3, :3])))


def _stack(name: str, T) -> np.ndarray:
    try:
        T = np.asarray(T, dtype=float)
    except (TypeError, ValueError) as e:
        raise HandEyeError(f"{name}: not a stack of 4x4 transforms ({e})") from None
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise HandEyeError(f"{name}: expected (N, 4, 4) transforms, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise HandEyeError(f"{name}: contains NaN or infinite values")
    for i, t in enumerate(T):
        try:
            check_rigid(t, tol=1e-6, name=f"{name}[{i}]")
        except ValueError as e:
            raise HandEyeError(str(e)) from None
    return T


def check_motion(world_T_flange_mm: np.ndarray, min_angle_deg: float = 2.0, min_axis_angle_deg: float = 5.0) -> None:
    """Raise :class:`HandEyeError` unless the flange's rotations determine X: at least 3
    poses whose rotations differ by ``min_angle_deg`` or more, and relative rotations about
    at least two axes at least ``min_axis_angle_deg`` apart (rotations about one axis leave
    X's translation along that axis unknown)."""
    A = np.asarray(world_T_flange_mm, dtype=float)
    if len(A) < MIN_POSES:
        raise HandEyeError(f"too few poses: {len(A)}; AX = YB needs at least {MIN_POSES} with rotations about "
                           "two non-parallel axes")
    distinct = [A[0]]
    for T in A[1:]:
        if all(np.degrees(rotation_angle_rad(T[:3, :3] @ D[:3, :3].T)) >= min_angle_deg for D in distinct):
            distinct.append(T)
    if len(distinct) < MIN_POSES:
        raise HandEyeError(f"too few distinct rotations: {len(distinct)} of {len(A)} poses differ by >= "
                           f"{min_angle_deg:g} deg; AX = YB needs at least {MIN_POSES} (rotations about two "
                           "non-parallel axes)")
    axes = []
    for i in range(len(distinct)):
        for j in range(i + 1, len(distinct)):
            r = rotvec_from_matrix(distinct[j][:3, :3] @ distinct[i][:3, :3].T)  # in the world frame
            axes.append(r / np.linalg.norm(r))
    axes = np.array(axes)
    # The widest angle between two rotation axes (a line: sign does not matter).
    cos = np.abs(axes @ axes.T).clip(0.0, 1.0)
    widest = float(np.degrees(np.arccos(cos.min())))
    if widest < min_axis_angle_deg:
        raise HandEyeError(f"degenerate motion: every relative rotation is about one axis (widest angle between "
                           f"axes {widest:.2f} deg < {min_axis_angle_deg:g} deg); tilt about a second axis")


def _project_so3(M: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(M)
    R = U @ Vt
    if np.linalg.det(R) < 0:
        R = U @ np.diag([1.0, 1.0, -1.0]) @ Vt
    return R


def closed_form_ax_yb(A: np.ndarray, camera_T_target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shah's closed form: (X, Y) (4, 4) from A = world_T_flange (N, 4, 4) and the
    measurements camera_T_target (N, 4, 4), mm. With ``B = target_T_camera`` (the
    measurement inverted) ``A X = Y B``, and ``R_A R_X = R_Y R_B`` gives ``(R_B (x) R_A) vec(R_X) = vec(R_Y)`` (column-major vec);
    the stacked system's null vector is [vec R_X; vec R_Y] up to scale. Then
    ``R_A t_X - t_Y = R_Y t_B - t_A`` by linear least squares."""
    B = np.array([invert_transform(T) for T in camera_T_target])
    n = len(A)
    M = np.zeros((9 * n, 18))
    for i in range(n):
        M[9 * i:9 * i + 9, :9] = np.kron(B[i, :3, :3], A[i, :3, :3])
        M[9 * i:9 * i + 9, 9:] = -np.eye(9)
    v = np.linalg.svd(M)[2][-1]
    Rx = v[:9].reshape(3, 3, order="F")
    Ry = v[9:].reshape(3, 3, order="F")
    s = np.sign(np.linalg.det(Rx)) or 1.0  # the null vector's sign is arbitrary
    Rx, Ry = _project_so3(s * Rx), _project_so3(s * Ry)
    C = np.zeros((3 * n, 6))
    d = np.zeros(3 * n)
    for i in range(n):
        C[3 * i:3 * i + 3, :3] = A[i, :3, :3]
        C[3 * i:3 * i + 3, 3:] = -np.eye(3)
        d[3 * i:3 * i + 3] = Ry @ B[i, :3, 3] - A[i, :3, 3]
    t = np.linalg.lstsq(C, d, rcond=None)[0]
    return make_transform(Rx, t[:3]), make_transform(Ry, t[3:])


def _residuals(A: np.ndarray, B: np.ndarray, X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pose, in the camera frame: B_i's translation error (N, 3) mm and rotation error
    (N, 3) rad (rotation vector of B_i pred^T), pred = inv(X) inv(A_i) Y."""
    Xi = invert_transform(X)
    pred = np.array([Xi @ invert_transform(a) @ Y for a in A])
    dt = B[:, :3, 3] - pred[:, :3, 3]
    dr = rotvec_from_matrix(np.einsum("nij,nkj->nik", B[:, :3, :3], pred[:, :3, :3]), assume_valid=True)
    return dt, dr.reshape(-1, 3)


def _perturb(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    """T with a rotation step p[:3] (rad, in T's own frame) and translation step p[3:] (mm)."""
    out = np.array(T, dtype=float)
    out[:3, :3] = T[:3, :3] @ matrix_from_rotvec(p[:3])
    out[:3, 3] += p[3:]
    return out


def solve_ax_yb(world_T_flange_mm, camera_T_target_mm, *, outlier_factor: float = 5.0,
                cross_check: bool = True, min_axis_angle_deg: float = 5.0) -> HandEyeResult:
    """Solve ``A_i X = Y B_i`` for X = flange_T_camera and Y = world_T_target (B_i the
    inverse of the measurement).

    ``world_T_flange_mm`` (N, 4, 4): the robot's flange poses (A). ``camera_T_target_mm``
    (N, 4, 4): the target measured in the camera frame at each (B). Raises
    :class:`HandEyeError` on too few poses, degenerate motion or bad transforms.
    ``outlier_factor``: the one pose whose residual (translation or rotation) exceeds this
    many times the median is dropped and the fit repeated, if the rest still determine X. ``cross_check``: also run OpenCV's solvers when
    available."""
    A = _stack("world_T_flange", world_T_flange_mm)
    B = _stack("camera_T_target", camera_T_target_mm)
    if len(A) != len(B):
        raise HandEyeError(f"{len(A)} robot poses but {len(B)} target measurements: give one of each per pose")
    check_motion(A, min_axis_angle_deg=min_axis_angle_deg)
    X0, Y0 = closed_form_ax_yb(A, B)
    used = np.ones(len(A), dtype=bool)
    X, Y, cov = _refine(A, B, X0, Y0)
    dt, dr = _residuals(A, B, X, Y)
    e_mm, e_deg = np.linalg.norm(dt, axis=1), np.degrees(np.linalg.norm(dr, axis=1))
    if len(A) > MIN_POSES + 1 and outlier_factor > 0:
        # Against the median (an outlier inflates an RMS and hides behind it).
        score = np.maximum(e_mm / max(float(np.median(e_mm)), 1e-9), e_deg / max(float(np.median(e_deg)), 1e-9))
        worst = int(np.argmax(score))
        if score[worst] > outlier_factor:
            keep = np.arange(len(A)) != worst
            try:
                check_motion(A[keep], min_axis_angle_deg=min_axis_angle_deg)
                X, Y, cov = _refine(A[keep], B[keep], X, Y)
                used = keep
                dt, dr = _residuals(A, B, X, Y)
                e_mm, e_deg = np.linalg.norm(dt, axis=1), np.degrees(np.linalg.norm(dr, axis=1))
            except HandEyeError:
                pass  # without it the motion degenerates: keep every pose
    sigma = _x_sigma(X, cov)
    if used.sum() >= 4:
        # Per-pose errors of a real measurement are not independent noise (a pose's bias
        # stays however long it is averaged), so the Gauss-Newton sigma can be too small:
        # take the larger of it and the jackknife's (leave one pose out).
        sigma = np.maximum(sigma, _jackknife_sigma(A[used], B[used], X, Y))
    checks, note = (opencv_cross_check(A[used], B[used]) if cross_check else ({}, "not asked for"))
    return HandEyeResult(X, Y, sigma, e_mm, e_deg, used, X0, checks, note)


def _refine(A, B, X0, Y0, passes: int = 4):
    """Nonlinear least squares from (X0, Y0); returns X, Y and the covariance (12, 12) of
    the steps (X rot rad, X trans mm, Y rot rad, Y trans mm).

    Each residual component (camera x, y, z of translation and of rotation) is weighed by
    its own spread, re-estimated from the fit a few times: a stereo camera measures depth
    and the tilt of the target worse than the image-plane position and the turn about its
    optical axis, and weighing them equally would let the worse ones pull X."""
    dt, dr = _residuals(A, B, X0, Y0)
    floor_t, floor_r = 1e-6, 1e-9  # a perfect start must not divide by zero
    s_t = np.full(3, max(_rms(dt), floor_t))
    s_r = np.full(3, max(_rms(dr), floor_r))

    def f(p):
        X, Y = _perturb(X0, p[:6]), _perturb(Y0, p[6:])
        et, er = _residuals(A, B, X, Y)
        return np.concatenate([(et / s_t).ravel(), (er / s_r).ravel()])

    p = np.zeros(12)
    for _ in range(passes):
        sol = least_squares(f, p, method="lm", x_scale="jac")
        p = sol.x
        et, er = _residuals(A, B, _perturb(X0, p[:6]), _perturb(Y0, p[6:]))
        # Per-axis spreads, but no axis trusted more than 10x the average (few poses).
        s_t = np.maximum(np.sqrt(np.mean(et**2, axis=0)), max(_rms(et) / 10, floor_t))
        s_r = np.maximum(np.sqrt(np.mean(er**2, axis=0)), max(_rms(er) / 10, floor_r))
    sol = least_squares(f, p, method="lm", x_scale="jac")
    X, Y = _perturb(X0, sol.x[:6]), _perturb(Y0, sol.x[6:])
    m, n = sol.fun.size, sol.x.size
    J = sol.jac
    s2 = float(sol.fun @ sol.fun) / max(m - n, 1)
    # The covariance of the steps about (X0, Y0); X = X0 exp(p) (rotation in X0's frame)
    # and the steps are small, so it is X's about the solution.
    cov = s2 * np.linalg.pinv(J.T @ J)
    return X, Y, cov


def _jackknife_sigma(A: np.ndarray, B: np.ndarray, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """1-sigma (6,) of X's X-vector (mm, deg) by the jackknife: refit without each pose
    in turn (from the full solution), ``sqrt((n - 1) / n * sum (x_i - mean)^2)``."""
    n = len(A)
    xs = []
    for i in range(n):
        keep = np.arange(n) != i
        Xi, _, _ = _refine(A[keep], B[keep], X, Y, passes=1)
        xs.append(x_from_transform(Xi))
    xs = np.array(xs)
    d = xs - xs.mean(axis=0)
    d[:, 3:] = (d[:, 3:] + 180.0) % 360.0 - 180.0
    return np.sqrt((n - 1) / n * np.sum(d**2, axis=0))


def _x_sigma(X: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """1-sigma (6,) of X as (x, y, z mm, yaw, pitch, roll deg) from the covariance of its
    step (rot rad, trans mm), by a numerical Jacobian of the X-vector."""
    x0 = x_from_transform(X)
    J = np.zeros((6, 6))
    h = 1e-6
    for k in range(6):
        p = np.zeros(6)
        p[k] = h
        d = x_from_transform(_perturb(X, p)) - x0
        d[3:] = (d[3:] + 180.0) % 360.0 - 180.0
        J[:, k] = d / h
    c = J @ cov[:6, :6] @ J.T
    return np.sqrt(np.clip(np.diag(c), 0.0, None))


def opencv_cross_check(A: np.ndarray, B: np.ndarray) -> tuple[dict[str, np.ndarray], str]:
    """X from OpenCV's solvers, when the installed OpenCV exports them (4.x does, 5.0 does
    not): ``calibrateRobotWorldHandEye`` (Shah's method) on the same poses, and
    ``calibrateHandEye`` (Tsai and Park, AX = XB on relative motions). Returns ({name:
    X (4, 4) mm}, a note: what ran or why not)."""
    import cv2

    out: dict[str, np.ndarray] = {}
    notes = []
    # OpenCV's names: "world" is our target, "base" our world, "gripper" our flange.
    R_t2c = [b[:3, :3] for b in B]
    t_t2c = [b[:3, 3].reshape(3, 1) for b in B]
    if hasattr(cv2, "calibrateRobotWorldHandEye"):
        Ainv = [invert_transform(a) for a in A]
        try:
            _, _, R_g2c, t_g2c = cv2.calibrateRobotWorldHandEye(
                R_world2cam=R_t2c, t_world2cam=t_t2c, R_base2gripper=[a[:3, :3] for a in Ainv],
                t_base2gripper=[a[:3, 3].reshape(3, 1) for a in Ainv],
                method=cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH)
            out["opencv robot-world (Shah)"] = invert_transform(make_transform(R_g2c, np.ravel(t_g2c)))
        except cv2.error as e:
            notes.append(f"calibrateRobotWorldHandEye failed: {str(e).strip().splitlines()[-1]}")
    else:
        notes.append("skipped calibrateRobotWorldHandEye (not in this OpenCV " + cv2.__version__ + ")")
    if hasattr(cv2, "calibrateHandEye"):
        for name, method in (("Tsai", cv2.CALIB_HAND_EYE_TSAI), ("Park", cv2.CALIB_HAND_EYE_PARK)):
            try:
                R_c2g, t_c2g = cv2.calibrateHandEye(
                    R_gripper2base=[a[:3, :3] for a in A], t_gripper2base=[a[:3, 3].reshape(3, 1) for a in A],
                    R_target2cam=R_t2c, t_target2cam=t_t2c, method=method)
                out[f"opencv AX=XB ({name})"] = make_transform(R_c2g, np.ravel(t_c2g))
            except cv2.error as e:
                notes.append(f"calibrateHandEye {name} failed: {str(e).strip().splitlines()[-1]}")
    else:
        notes.append("skipped calibrateHandEye (not in this OpenCV " + cv2.__version__ + ")")
    return out, "; ".join(notes)


def apply_to_rig(rig: Rig, result: HandEyeResult, date: str) -> Rig:
    """``rig`` with its hand-eye replaced by ``result``'s X: ``flange_T_camera_x`` and a
    Calibration (method ``ax=yb``, ``date``, a note with the residuals, sigma: the largest
    1-sigma of X's six elements, mm for x, y, z and deg for the angles)."""
    x = tuple(float(v) for v in result.flange_T_camera_x)
    s = result.flange_T_camera_sigma
    u = result.used
    note = (f"{result.n_poses} poses; residual RMS {_rms(result.residual_mm[u]):.4f} mm, "
            f"{_rms(result.residual_deg[u]):.4f} deg; 1-sigma {float(s[:3].max()):.4f} mm, {float(s[3:].max()):.4f} deg")
    cal = Calibration(method=METHOD, date=date, note=note, sigma={"flange_T_camera_x": round(float(s.max()), 6)})
    rig = dataclasses.replace(rig, hand_eye=HandEye(flange_T_camera_x=x, calibration=cal))
    if result.time_offset is not None:
        from humanpt.calibration import timing

        rig = timing.apply_to_rig(rig, result.time_offset, date)
    return rig


# --------------------------------------------------------------------------- planning the poses

def plan_poses(world_T_flange_start_mm: np.ndarray, flange_T_camera_mm: np.ndarray, dz_mm: float, *,
               n_poses: int = 12, tilt_deg: tuple[float, float] = (10.0, 20.0), roll_deg: float = 15.0,
               distance_mm: float = 60.0, off_axis_deg: float = 4.0, envelope_min_mm=None, envelope_max_mm=None,
               check: Callable[[np.ndarray, np.ndarray], str | None] | None = None,
               seed: int = 0) -> tuple[np.ndarray, list[str]]:
    """Flange poses (n, 4, 4) mm around a target seen on the optical axis at ``dz_mm``
    from ``world_T_flange_start_mm`` (as the rig's ``flange_T_camera_mm`` says): the camera
    tilted about the target by ``tilt_deg`` (min, max) about its x and y axes (alternating
    signs and axes), turned about its optical axis by up to ``roll_deg`` and moved along
    it by up to ``distance_mm``, and turned about the camera's centre by ``off_axis_deg``
    so the target sits that far off the optical axis, in a different direction each pose
    (with the target always on the axis, a turn of the camera about its own axis would not
    move the target, and X's rotation about it would rest on the measured orientation
    alone). Poses whose flange
    leaves the envelope (world mm, inclusive; None: no check) are dropped with a note, and
    so are those for which ``check(from_pose, to_pose)`` (the robot's own test of the move
    from the previous pose, e.g. its kinematics: a singularity or a joint limit on the
    way) returns a reason. Returns (poses, notes). The start pose is the first."""
    rng = np.random.default_rng(seed)
    F0 = np.asarray(world_T_flange_start_mm, dtype=float)
    C = np.asarray(flange_T_camera_mm, dtype=float)
    W_cam0 = F0 @ C
    poses, notes = [F0.copy()], []
    lo, hi = tilt_deg
    k = 0
    while len(poses) < n_poses and k < 4 * n_poses:
        k += 1
        axis = k % 2  # alternate x and y tilts
        sign = 1.0 if (k // 2) % 2 == 0 else -1.0
        tilt = np.radians(rng.uniform(lo, hi)) * sign
        other = np.radians(rng.uniform(-lo, lo) / 2)  # a smaller tilt about the other axis
        rv = np.zeros(3)
        rv[axis], rv[1 - axis] = tilt, other
        rv[2] = np.radians(rng.uniform(-roll_deg, roll_deg))
        d = dz_mm + rng.uniform(-distance_mm, distance_mm)
        # camera0_T_camera: turned about the target point (0, 0, dz) of camera 0, at distance d.
        R = matrix_from_rotvec(rv)
        target = np.array([0.0, 0.0, dz_mm])
        c0_T_c = make_transform(R, target - R @ np.array([0.0, 0.0, d]))
        phi = rng.uniform(0.0, 2 * np.pi)
        off = np.radians(off_axis_deg) * np.array([np.cos(phi), np.sin(phi), 0.0])
        c0_T_c = c0_T_c @ make_transform(matrix_from_rotvec(off), np.zeros(3))
        F = W_cam0 @ c0_T_c @ invert_transform(C)
        p = F[:3, 3]
        if envelope_min_mm is not None and envelope_max_mm is not None and (
                np.any(p < np.asarray(envelope_min_mm)) or np.any(p > np.asarray(envelope_max_mm))):
            notes.append(f"planned pose {k} leaves the workspace envelope at {np.round(p, 1).tolist()} mm: skipped")
            continue
        why = check(poses[-1], F) if check is not None else None
        if why:
            notes.append(f"planned pose {k}: {why}: skipped")
            continue
        poses.append(F)
    return np.array(poses), notes


def puma_move_check(world_T_base_mm_deg, model: str = "puma762", min_wrist_deg: float = 8.0,
                    max_step_deg: float = 3.0, samples: int = 40) -> Callable[[np.ndarray, np.ndarray], str | None]:
    """The robot's own test of a planned move (the nominal Puma model,
    :mod:`humanpt.geometry.puma`, where the gateway believes the base is, as a real cell's
    planner would use its robot's model): the straight move from one flange pose to the next
    (world, mm) must stay reachable, keep the wrist (q5) ``min_wrist_deg`` from its
    singularity and never jump more than ``max_step_deg`` in a joint between ``samples``
    points (a branch flip). The first pose's branch is the one nearest the Puma's home
    joints (:data:`humanpt.geometry.puma.HOME_JOINTS_DEG`)."""
    kin = PumaKinematics(RobotModelConfig(model=model))
    base_T_world = invert_transform(transform_from_x(np.asarray(world_T_base_mm_deg, dtype=float)))
    q_home = np.radians(np.asarray(HOME_JOINTS_DEG, dtype=float))

    def check(a: np.ndarray, b: np.ndarray) -> str | None:
        try:
            q = kin.inverse(base_T_world @ a, q_home)
            for s in np.linspace(0.0, 1.0, samples)[1:]:
                qn = kin.inverse(base_T_world @ interpolate_transform(a, b, s), q)
                if np.degrees(np.abs(qn - q)).max() > max_step_deg:
                    return "the move flips a joint (a singularity on the way)"
                if abs(np.degrees(qn[4])) < min_wrist_deg:
                    return f"the move passes within {min_wrist_deg:g} deg of the wrist singularity"
                q = qn
        except UnreachableError as e:
            return f"unreachable ({e})"
        return None

    return check



# --------------------------------------------------------------------------- collecting the pairs

def mean_transform(T: np.ndarray) -> np.ndarray:
    """The mean of a few close poses (n, 4, 4): translations averaged, rotation the
    chordal mean (the mean matrix projected onto SO(3))."""
    T = np.asarray(T, dtype=float)
    return make_transform(_project_so3(T[:, :3, :3].mean(axis=0)), T[:, :3, 3].mean(axis=0))


@dataclass(frozen=True)
class CollectorSettings:
    """How :class:`PoseCollector` waits at each pose.

    ``move_timeout_s``: a pose not reached by then is skipped (unreachable, clamped).
    ``settle_s``: still time after arriving before measuring. ``average_s``: how long the
    measurements are averaged. ``min_measurements``: fewer FULL measurements in that
    window and the pose is skipped (target not seen). ``reach_tol_mm``/``reach_tol_deg``:
    how far the robot may end from the planned pose (a gateway clamp ends it elsewhere).
    ``still_mm``: the flange must move less than this during the window.
    ``max_missed_in_a_row``: after this many poses in a row not reached, give up (the
    robot is not moving at all)."""

    move_timeout_s: float = 8.0
    settle_s: float = 0.3
    average_s: float = 1.0
    min_measurements: int = 10
    reach_tol_mm: float = 1.0
    reach_tol_deg: float = 0.2
    still_mm: float = 0.05
    max_missed_in_a_row: int = 3


@dataclass
class PoseSample:
    """One collected pair: pose index, A = world_T_flange (mean over the window, mm), B =
    camera_T_target (mean, mm) and how many measurements went into B."""

    index: int
    world_T_flange_mm: np.ndarray
    camera_T_target_mm: np.ndarray
    measurements: int
    spread_mm: float  # RMS of the measured translations about their mean


class PoseCollector:
    """The robot moves itself through planned flange poses and collects (A, B) pairs:
    a state machine fed with robot states, target measurements and controller events
    (any shell: the lock-step twin or a live cell over Zenoh), that says which console
    command to send next.

    Drive it: ``cmd = c.start(t_ns)``; then for each message ``c.on_robot_state(t_ns,
    world_T_flange_mm)``, ``c.on_measurement(t_ns, camera_T_target_mm or None)``,
    ``c.on_controller_event(t_ns, code, text)`` (and ``c.end(why)`` when the robot
    faults), and after each ``cmd = c.poll(t_ns)``: a
    (verb, args) to send to the controller, or None. ``c.done`` when finished; ``c.samples``
    the pairs, ``c.notes`` what was skipped and why, ``c.aborted`` why it stopped early.

    It moves the robot with the controller's ``playback`` verb (one point: the tool pose
    that puts the flange on the planned pose), so every motion goes through the normal
    command path (controller -> robot_gateway -> robot, with their limits) and the
    console's ``stop`` ends it."""

    def __init__(self, world_T_flange_mm: np.ndarray, flange_T_tool_mm: np.ndarray,
                 settings: CollectorSettings | None = None, speed_mm_s: float = 50.0):
        self.poses = np.asarray(world_T_flange_mm, dtype=float)
        self.flange_T_tool = np.asarray(flange_T_tool_mm, dtype=float)
        self.s = settings or CollectorSettings()
        self.speed_mm_s = float(speed_mm_s)
        self.samples: list[PoseSample] = []
        self.notes: list[str] = []
        self.aborted = ""
        self.i = -1
        self.state = "idle"
        self._since = 0
        self._pending: tuple[str, dict] | None = None
        self._robot: list[tuple[int, np.ndarray]] = []
        self._meas: list[np.ndarray] = []
        self._seen = 0
        self._last_robot: np.ndarray | None = None

    @property
    def done(self) -> bool:
        return self.state == "done"

    def progress(self) -> tuple[int, int]:
        """(poses finished, poses planned)."""
        return max(self.i, 0), len(self.poses)

    def start(self, t_ns: int) -> tuple[str, dict]:
        self._next_pose(t_ns)
        return self.poll(t_ns)

    def _next_pose(self, t_ns: int) -> None:
        self.i += 1
        if self.i >= len(self.poses):
            self.state = "done"
            self._pending = ("hold", {})
            return
        tool = self.poses[self.i] @ self.flange_T_tool
        self._pending = ("playback", {"points": [[round(float(v), 6) for v in x_from_transform(tool)]],
                                      "speed_mm_s": self.speed_mm_s})
        self.state, self._since = "moving", t_ns

    def _skip(self, t_ns: int, why: str) -> None:
        # The next playback replaces this one at the controller: no hold in between (a
        # hold while collecting means someone stopped it).
        self.notes.append(f"pose {self.i}: skipped, {why}")
        self._next_pose(t_ns)

    def poll(self, t_ns: int) -> tuple[str, dict] | None:
        """The next console command for the controller, if one is due."""
        cmd, self._pending = self._pending, None
        if cmd is None and self.state == "moving" and t_ns - self._since > self.s.move_timeout_s * 1e9:
            self._missed = getattr(self, "_missed", 0) + 1
            if self._missed >= self.s.max_missed_in_a_row:
                self.end(f"{self._missed} poses in a row not reached in {self.s.move_timeout_s:g} s each: "
                         "the robot is not following (unreachable, clamped or not in ALTER)")
            else:
                self._skip(t_ns, f"not reached in {self.s.move_timeout_s:g} s (unreachable or clamped by the gateway)")
            return self.poll(t_ns)
        if cmd is None and self.state == "settling" and t_ns - self._since >= self.s.settle_s * 1e9:
            self.state, self._since = "averaging", t_ns
            self._robot, self._meas, self._seen = [], [], 0
        if cmd is None and self.state == "averaging" and t_ns - self._since >= self.s.average_s * 1e9:
            self._finish_pose(t_ns)
            return self.poll(t_ns)
        return cmd

    def stop(self, why: str) -> None:
        """End now (e.g. the console said stop): no further command but ``hold``."""
        if self.state != "done":
            self.aborted = why
            self.state = "done"
            self._pending = ("hold", {})

    def end(self, why: str) -> None:
        """End now with what has been collected (e.g. the robot faulted: no further pose
        can be reached); ``why`` goes to the notes."""
        if self.state != "done":
            self.notes.append(f"pose {self.i}: collection ended, {why}")
            self.state = "done"
            self._pending = ("hold", {})

    def on_robot_state(self, t_ns: int, world_T_flange_mm: np.ndarray) -> None:
        self._last_robot = np.asarray(world_T_flange_mm, dtype=float)
        if self.state == "averaging":
            self._robot.append((t_ns, self._last_robot))

    def on_measurement(self, t_ns: int, camera_T_target_mm: np.ndarray | None) -> None:
        """A measurement of the target (None: not FULL)."""
        if self.state == "averaging":
            self._seen += 1
            if camera_T_target_mm is not None:
                self._meas.append(np.asarray(camera_T_target_mm, dtype=float))

    def on_controller_event(self, t_ns: int, code: str, text: str) -> None:
        if code == "playback_done" and self.state == "moving":
            self.state, self._since, self._missed = "settling", t_ns, 0
        elif code == "command" and text.startswith("hold") and self.state in ("moving", "settling", "averaging"):
            self.stop("stopped by a console command (hold/stop)")
        elif code == "bad_command" and self.state == "moving":
            self._skip(t_ns, f"the controller refused it: {text}")

    def _finish_pose(self, t_ns: int) -> None:
        s = self.s
        if len(self._meas) < s.min_measurements:
            self._skip(t_ns, f"target seen in {len(self._meas)} of {self._seen} images (< {s.min_measurements})")
            return
        if not self._robot:
            self._skip(t_ns, "no robot state while measuring")
            return
        A = np.array([T for _, T in self._robot])
        moved = float(np.ptp(A[:, :3, 3], axis=0).max())
        if moved > s.still_mm:
            self._skip(t_ns, f"the flange moved {moved:.3f} mm while measuring (> {s.still_mm:g} mm)")
            return
        Am = mean_transform(A)
        dt, da = pose_difference(Am, self.poses[self.i])
        if dt > s.reach_tol_mm or da > s.reach_tol_deg:
            self._skip(t_ns, f"the robot stopped {dt:.2f} mm, {da:.3f} deg from the planned pose (clamped?)")
            return
        Bs = np.array(self._meas)
        Bm = mean_transform(Bs)
        spread = float(np.sqrt(np.mean(np.sum((Bs[:, :3, 3] - Bm[:3, 3]) ** 2, axis=1))))
        self.samples.append(PoseSample(self.i, Am, Bm, len(Bs), spread))
        self._next_pose(t_ns)
