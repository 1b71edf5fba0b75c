"""Kinematic calibration of the arm that plays (issue 32.4): its joint zero offsets and DH
length errors, from the PSVS's measurements of a fixed target over N robot poses, jointly
with the hand-eye transform and the target's world pose.

The robot (a Puma over ALTER) reports its flange as its *nominal* model puts it
(``world_T_base @ PumaKinematics.forward(q)``); the physical arm
(:class:`humanpt.geometry.puma.TrueArm`) has DH lengths off by a few tenths of a mm and
joint zeros off by a few hundredths of a degree: about 1 mm of absolute error.  The camera
on the flange sees a target held still (the TOB on its fixture, as for the hand-eye).  Pose
i gives the joints ``q_i`` (the nominal inverse kinematics of the reported flange, the
branch closest to the one before) and the measurement ``camera_T_target_i``; the unknowns
are the arm's errors ``p``, ``X = flange_T_camera`` and ``Y = world_T_target``::

    camera_T_target_i = inv(X) inv(world_T_base F(q_i; p)) Y

solved by ``scipy.optimize.least_squares`` from the hand-eye's AX = YB solution on the
nominal arm (:func:`humanpt.calibration.handeye.solve_ax_yb`) and ``p = 0``, the residual
of each camera axis weighted by its own spread (as the hand-eye's refinement); 1-sigma from
the Gauss-Newton covariance (the Jacobian, scaled by the residuals).

What the data can tell (the model's identifiable set).  Of the 11 errors
:class:`~humanpt.geometry.puma.TrueArm` has (six joint offsets; d2, a2, a3, d4, d6), three
are never observable from a camera on the flange looking at a fixed target, and are held
at 0 (:data:`UNOBSERVABLE`): joint 1's offset (a turn of the whole arm about joint 1's
axis, the base z: the target's unknown world pose takes it), joint 6's offset and d6 (a
turn about and a shift along the flange's z axis: the unknown hand-eye takes them).  None
of the three matters for a seam the same arm teaches and plays (the first is a turn of the
frame both happen in; the camera's share of the other two is in the hand-eye), except d6's
and joint 6's share at the torch, which is the tool's own (TCP) calibration.  Of the
eight others each one whose 1-sigma from the data is larger than :data:`MAX_SIGMA` (the
poses do not move the joints it needs) is held at 0 as well, one at a time, the least
determined first, and named with its sigma (``ArmResult.fixed``).

Units: mm and radians inside (as :mod:`humanpt.geometry.puma`), mm and degrees in the
result; (4, 4) ``a_T_b`` transforms, stacks (N, 4, 4).  Pure: no clock, no I/O.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from humanpt.geometry.puma import (
    HOME_JOINTS_DEG,
    PumaKinematics,
    RobotModelConfig,
    TrueArm,
    UnreachableError,
    follow,
    perturbed_geometry,
)
from humanpt.geometry.rig import Arm, Calibration, HandEye, Rig
from humanpt.geometry.transforms import invert_transform, x_from_transform

from .handeye import HandEyeError, _perturb, _residuals, _rms, _stack, _x_sigma, solve_ax_yb

__all__ = ["ArmCalibrationError", "ArmResult", "PARAMETERS", "UNOBSERVABLE", "MAX_SIGMA", "MIN_POSES", "METHOD",
           "solve_arm", "joints_of", "true_world_T_flange", "correct_path", "apply_to_rig", "simulate_measurements"]

METHOD = "arm+ax=yb"
"""The rig's ``arm.calibration.method`` (and the hand-eye's) this tool writes."""

# The 11 errors of the arm, in the order of TrueArm's (joint offsets, then perturbed_geometry's lengths).
PARAMETERS = ("q1_offset_deg", "q2_offset_deg", "q3_offset_deg", "q4_offset_deg", "q5_offset_deg",
              "q6_offset_deg", "d2_mm", "a2_mm", "a3_mm", "d4_mm", "d6_mm")
UNOBSERVABLE = {
    "q1_offset_deg": "a turn of the whole arm about joint 1's axis: the target's world pose takes it",
    "q6_offset_deg": "a turn about the flange's axis: the hand-eye takes it",
    "d6_mm": "a shift along the flange's axis: the hand-eye takes it",
}
# A parameter the data determine worse than this (1-sigma) is held at 0: an estimate that
# uncertain would move the model more than the error it corrects (the realistic world's
# are 0.02-0.03 deg and 0.1-0.3 mm).
MAX_SIGMA = {"deg": 0.02, "mm": 0.2}
# Poses: 6 numbers each against 8 arm errors and 12 of X and Y, with room to spare.
MIN_POSES = 8
# The least noise a measurement is taken to have (1-sigma per pose: translation mm, rotation
# deg): the sigmas of noise-free (synthetic) data then still say which errors the poses
# determine, and how well, instead of all being 0.
FLOOR_MM, FLOOR_DEG = 0.002, 0.0005


class ArmCalibrationError(ValueError):
    """Input the arm's calibration cannot use; the message says what and why, in one line."""


def _unit(name: str) -> str:
    return "deg" if name.endswith("_deg") else "mm"


@dataclass(frozen=True)
class ArmResult:
    """The arm's errors against its nominal ``model`` with their 1-sigma (0 for a
    parameter held at 0), the hand-eye X and the target's pose Y estimated with them, and
    per pose how far the measured target is from where the model puts it: after
    (``residual_mm``/``_deg``) and with the nominal arm (the hand-eye alone,
    ``nominal_residual_mm``/``_deg``).  ``fixed``: {parameter: why it is held at 0}."""

    model: str
    joint_offsets_deg: np.ndarray
    link_length_errors_mm: np.ndarray
    joint_offsets_sigma_deg: np.ndarray
    link_length_errors_sigma_mm: np.ndarray
    fixed: dict[str, str]
    flange_T_camera_mm: np.ndarray
    world_T_target_mm: np.ndarray
    flange_T_camera_sigma: np.ndarray
    residual_mm: np.ndarray
    residual_deg: np.ndarray
    nominal_residual_mm: np.ndarray
    nominal_residual_deg: np.ndarray
    joints_rad: np.ndarray
    notes: list[str] = field(default_factory=list)

    @property
    def n_poses(self) -> int:
        return len(self.residual_mm)

    @property
    def identified(self) -> tuple[str, ...]:
        return tuple(p for p in PARAMETERS if p not in self.fixed)

    def values(self) -> dict[str, tuple[float, float]]:
        """{parameter: (estimate, 1-sigma)} in deg or mm (PARAMETERS' order)."""
        v = np.r_[self.joint_offsets_deg, self.link_length_errors_mm]
        s = np.r_[self.joint_offsets_sigma_deg, self.link_length_errors_sigma_mm]
        return {p: (float(a), float(b)) for p, a, b in zip(PARAMETERS, v, s, strict=True)}

    def true_arm(self) -> TrueArm:
        """The calibrated arm's forward kinematics (base_T_flange, mm, at encoder angles)."""
        geometry = perturbed_geometry(RobotModelConfig(model=self.model).geometry, self.link_length_errors_mm)
        return TrueArm(geometry, np.radians(self.joint_offsets_deg))

    def summary_lines(self) -> list[str]:
        lines = [f"arm ({self.model}) calibrated with the hand-eye from {self.n_poses} poses: "
                 f"{len(self.identified)} of {len(PARAMETERS)} errors identified"]
        for p, (v, s) in self.values().items():
            if p in self.fixed:
                lines.append(f"  {p:14s} held at 0: {self.fixed[p]}")
            else:
                lines.append(f"  {p:14s} {v:+.4f} +- {s:.4f} {_unit(p)}")
        lines.append(f"  residual: translation RMS {_rms(self.residual_mm):.4f} mm, max {self.residual_mm.max():.4f} mm; "
                     f"rotation RMS {_rms(self.residual_deg):.4f} deg (the nominal arm: "
                     f"{_rms(self.nominal_residual_mm):.4f} mm, {_rms(self.nominal_residual_deg):.4f} deg)")
        x, s = x_from_transform(self.flange_T_camera_mm), self.flange_T_camera_sigma
        lines.append("  flange_T_camera (X) with it: [" + ", ".join(f"{v:.4f}" for v in x) + "] mm/deg, 1-sigma up to "
                     f"{float(s[:3].max()):.4f} mm, {float(s[3:].max()):.4f} deg")
        lines += [f"  {n}" for n in self.notes]
        return lines


def joints_of(world_T_flange_mm: np.ndarray, world_T_base_mm: np.ndarray, kin: PumaKinematics,
              q_ref_rad: np.ndarray | None = None) -> np.ndarray:
    """(N, 6) the joints (rad) behind reported flange poses (N, 4, 4) mm: the nominal
    inverse kinematics (the model that reported them), each on the branch closest to the
    joints before, the first closest to ``q_ref_rad`` (default the Puma's home joints)."""
    q_ref = np.radians(HOME_JOINTS_DEG) if q_ref_rad is None else np.asarray(q_ref_rad, dtype=float)
    base_T_world = invert_transform(np.asarray(world_T_base_mm, dtype=float))
    try:
        return follow(kin, base_T_world @ np.asarray(world_T_flange_mm, dtype=float).reshape(-1, 4, 4), q_ref)
    except UnreachableError as e:
        raise ArmCalibrationError(f"a reported flange pose is out of the nominal arm's reach ({e}): is "
                                  "world_T_base the robot's mounting?") from None


def _arm(model: str, p: np.ndarray) -> TrueArm:
    """TrueArm of the 11 errors ``p`` (joint offsets rad, lengths mm)."""
    return TrueArm(perturbed_geometry(RobotModelConfig(model=model).geometry, p[6:]), p[:6])


def _scale(name: str) -> float:
    """Parameter units inside -> outside (rad -> deg, mm -> mm)."""
    return float(np.degrees(1.0)) if name.endswith("_deg") else 1.0


def solve_arm(world_T_flange_mm, camera_T_target_mm, world_T_base_mm, *, model: str = "puma762",
              q_ref_rad: np.ndarray | None = None, max_sigma: dict[str, float] | None = None,
              passes: int = 3, rotation_weight: float = 1.0) -> ArmResult:
    """The arm's errors, X and Y from the reported flange poses ``world_T_flange_mm`` (N,
    4, 4) (the robot's nominal account, where its gateway says the base is:
    ``world_T_base_mm``) and the target measured in the camera frame at each
    ``camera_T_target_mm`` (N, 4, 4), the target still (module doc).  ``q_ref_rad``: the
    joints near the first pose (the branch).  ``rotation_weight``: the measured rotations'
    weight against the translations' (each already weighed by its own spread; 0: positions
    alone).  Raises :class:`ArmCalibrationError` on too
    few poses, bad transforms or degenerate motion; nothing else is written."""
    try:
        A = _stack("world_T_flange", world_T_flange_mm)
        B = _stack("camera_T_target", camera_T_target_mm)
    except HandEyeError as e:
        raise ArmCalibrationError(str(e)) from None
    if len(A) != len(B):
        raise ArmCalibrationError(f"{len(A)} robot poses but {len(B)} target measurements: give one of each per pose")
    if len(A) < MIN_POSES:
        raise ArmCalibrationError(f"too few poses: {len(A)}; the arm's calibration needs at least {MIN_POSES} "
                                  f"(8 arm errors, the hand-eye and the target's pose: 20 unknowns)")
    limits = dict(MAX_SIGMA if max_sigma is None else max_sigma)
    W = np.asarray(world_T_base_mm, dtype=float)
    kin = PumaKinematics(RobotModelConfig(model=model))
    q = joints_of(A, W, kin, q_ref_rad)
    try:
        he = solve_ax_yb(A, B, cross_check=False, outlier_factor=0.0)
    except HandEyeError as e:
        raise ArmCalibrationError(f"the hand-eye on the nominal arm, the start: {e}") from None
    X0, Y0 = he.flange_T_camera_mm, he.world_T_target_mm
    free = [i for i, p in enumerate(PARAMETERS) if p not in UNOBSERVABLE]
    fixed = dict(UNOBSERVABLE)
    notes: list[str] = []
    while True:
        p, X, Y, cov, n_free = _fit(model, q, W, A, B, X0, Y0, free, passes, rotation_weight)
        sigma = np.sqrt(np.clip(np.diag(cov)[:n_free], 0.0, None)) * np.array([_scale(PARAMETERS[i]) for i in free])
        ratio = np.array([s / limits[_unit(PARAMETERS[i])] for s, i in zip(sigma, free, strict=True)])
        if not len(free) or ratio.max() <= 1.0:
            break
        worst = int(np.argmax(ratio))
        name = PARAMETERS[free[worst]]
        fixed[name] = (f"not determined by these poses (1-sigma {sigma[worst]:.3g} {_unit(name)} > "
                       f"{limits[_unit(name)]:g})")
        free = [i for i in free if i != free[worst]]
    sig_full = np.zeros(len(PARAMETERS))
    sig_full[free] = sigma
    out = np.array([_scale(n) for n in PARAMETERS])
    A_fit = np.array([W @ T for T in _forward_all(_arm(model, p), q)])
    dt, dr = _residuals(A_fit, B, X, Y)
    dt0, dr0 = _residuals(A, B, X0, Y0)
    x_sigma = _x_sigma(X, cov[n_free:n_free + 6, n_free:n_free + 6])
    return ArmResult(model, p[:6] * out[:6], p[6:], sig_full[:6], sig_full[6:], fixed, X, Y, x_sigma,
                     np.linalg.norm(dt, axis=1), np.degrees(np.linalg.norm(dr, axis=1)),
                     np.linalg.norm(dt0, axis=1), np.degrees(np.linalg.norm(dr0, axis=1)), q, notes)


def _forward_all(arm: TrueArm, q: np.ndarray) -> np.ndarray:
    return np.array([arm.forward(qi) for qi in q])


def _fit(model, q, W, A, B, X0, Y0, free, passes, rotation_weight=1.0):
    """least_squares over (the free arm errors, X's step, Y's step), the residual of each
    camera axis weighted by its spread (re-estimated each pass).  Returns (p (11,), X, Y,
    the covariance of (free, X step, Y step), the number of free errors)."""
    nf = len(free)
    floor_t, floor_r = FLOOR_MM, np.radians(FLOOR_DEG)

    def unpack(z):
        p = np.zeros(len(PARAMETERS))
        p[free] = z[:nf]
        return p, _perturb(X0, z[nf:nf + 6]), _perturb(Y0, z[nf + 6:])

    def raw(z):
        p, X, Y = unpack(z)
        Af = np.array([W @ T for T in _forward_all(_arm(model, p), q)])
        return _residuals(Af, B, X, Y)

    z = np.zeros(nf + 12)
    et, er = raw(z)
    s_t = np.full(3, max(_rms(et), floor_t))
    s_r = np.full(3, max(_rms(er), floor_r))

    def f(z):
        et, er = raw(z)
        return np.concatenate([(et / s_t).ravel(), (rotation_weight * er / s_r).ravel()])

    for k in range(passes + 1):
        sol = least_squares(f, z, method="lm", x_scale="jac")
        z = sol.x
        if k < passes:
            et, er = raw(z)
            s_t = np.maximum(np.sqrt(np.mean(et**2, axis=0)), max(_rms(et) / 10, floor_t))
            s_r = np.maximum(np.sqrt(np.mean(er**2, axis=0)), max(_rms(er) / 10, floor_r))
    m, n = sol.fun.size, sol.x.size
    # The residuals are weighed by their spreads (at least the floor): s2 is about 1, or
    # below when the data are cleaner than the floor (then the floor's noise is taken).
    s2 = max(float(sol.fun @ sol.fun) / max(m - n, 1), 1.0)
    # (J^T J)^-1 by the SVD, a direction the data do not determine (a singular value at the
    # rounding level) given a huge variance rather than dropped as a pseudo-inverse would.
    _, sv, Vt = np.linalg.svd(sol.jac, full_matrices=False)
    sv = np.maximum(sv, sv.max() * 1e-12)
    cov = s2 * (Vt.T / sv**2) @ Vt
    p, X, Y = unpack(z)
    return p, X, Y, cov, nf


# --------------------------------------------------------------------------- using it


def true_world_T_flange(arm: TrueArm, world_T_flange_reported_mm: np.ndarray, world_T_base_mm: np.ndarray,
                        kin: PumaKinematics, q_ref_rad: np.ndarray | None = None) -> np.ndarray:
    """(N, 4, 4) where the calibrated ``arm`` puts the flange when the robot reports
    ``world_T_flange_reported_mm`` (N, 4, 4) by its nominal model ``kin`` (mounted at
    ``world_T_base_mm``): the same joints, the calibrated forward kinematics."""
    W = np.asarray(world_T_base_mm, dtype=float)
    q = joints_of(world_T_flange_reported_mm, W, kin, q_ref_rad)
    return np.array([W @ T for T in _forward_all(arm, q)])


def correct_path(x_mm_deg: np.ndarray, stamps_ns: np.ndarray, robot_stamps_ns: np.ndarray,
                 world_T_flange_reported_mm: np.ndarray, arm: TrueArm, world_T_base_mm: np.ndarray,
                 kin: PumaKinematics, q_ref_rad: np.ndarray | None = None) -> np.ndarray:
    """A taught path (N, 6) mm/deg (world poses the pipeline made from the robot's reported
    flange, the hand-eye and the camera) moved to where the calibrated ``arm`` says it was:
    each point by ``true_world_T_flange @ inv(reported)`` of the robot state nearest its
    stamp (``robot_stamps_ns`` (M,) with ``world_T_flange_reported_mm`` (M, 4, 4)); the
    correction changes by micrometres over a cycle's motion."""
    from humanpt.geometry.transforms import transform_from_x

    x = np.asarray(x_mm_deg, dtype=float).reshape(-1, 6)
    if not len(x):
        return x.copy()
    rs = np.asarray(robot_stamps_ns, dtype=np.int64).reshape(-1)
    R = np.asarray(world_T_flange_reported_mm, dtype=float).reshape(-1, 4, 4)
    if len(rs) != len(R) or not len(rs):
        raise ArmCalibrationError(f"{len(rs)} robot stamps for {len(R)} robot poses: the path cannot be corrected")
    order = np.argsort(rs, kind="stable")
    rs, R = rs[order], R[order]
    i = np.clip(np.searchsorted(rs, np.asarray(stamps_ns, dtype=np.int64)), 0, len(rs) - 1)
    j = np.clip(i - 1, 0, len(rs) - 1)
    s = np.asarray(stamps_ns, dtype=np.int64)
    near = np.where(np.abs(rs[j] - s) < np.abs(rs[i] - s), j, i)
    used = np.unique(near)
    T_true = true_world_T_flange(arm, R[used], world_T_base_mm, kin, q_ref_rad)
    C = {int(k): T @ invert_transform(R[k]) for k, T in zip(used, T_true, strict=True)}
    return x_from_transform(np.array([C[int(k)] @ transform_from_x(xi) for k, xi in zip(near, x, strict=True)]))


def apply_to_rig(rig: Rig, result: ArmResult, date: str) -> Rig:
    """``rig`` with the arm's errors (``[arm]``, with their 1-sigma: the largest of the
    joint offsets' in deg and of the lengths' in mm; which are held at 0 in the note) and
    the hand-eye estimated with them (``[hand_eye]``, method ``arm+ax=yb``)."""
    s = result.flange_T_camera_sigma
    fixed = ", ".join(result.fixed)
    note = (f"{result.n_poses} poses; residual RMS {_rms(result.residual_mm):.4f} mm, {_rms(result.residual_deg):.4f} deg "
            f"(nominal arm {_rms(result.nominal_residual_mm):.4f} mm); " + "; ".join(
                f"{p} {v:+.4f} +- {e:.4f}" for p, (v, e) in result.values().items() if p not in result.fixed)
            + f"; held at 0: {fixed}")
    cal = Calibration(method=METHOD, date=date, note=note,
                      sigma={"joint_offsets_deg": round(float(result.joint_offsets_sigma_deg.max()), 6),
                             "link_length_errors_mm": round(float(result.link_length_errors_sigma_mm.max()), 6)})
    arm = Arm(model=result.model, joint_offsets_deg=tuple(float(v) for v in result.joint_offsets_deg),
              link_length_errors_mm=tuple(float(v) for v in result.link_length_errors_mm), calibration=cal)
    he_note = f"estimated with the arm's errors ([arm]); 1-sigma {float(s[:3].max()):.4f} mm, {float(s[3:].max()):.4f} deg"
    hand_eye = HandEye(flange_T_camera_x=tuple(float(v) for v in x_from_transform(result.flange_T_camera_mm)),
                       calibration=Calibration(method=METHOD, date=date, note=he_note,
                                               sigma={"flange_T_camera_x": round(float(s.max()), 6)}))
    return dataclasses.replace(rig, arm=arm, hand_eye=hand_eye)


def simulate_measurements(arm: TrueArm, q_rad: np.ndarray, world_T_base_mm: np.ndarray,
                          flange_T_camera_mm: np.ndarray, world_T_target_mm: np.ndarray,
                          kin: PumaKinematics) -> tuple[np.ndarray, np.ndarray]:
    """What a cell would give at joints ``q_rad`` (N, 6): the reported flanges (the
    nominal model's, (N, 4, 4)) and the target in the camera frame as the physical ``arm``
    places the camera (N, 4, 4), noise-free: the tests' and the budget's synthetic data."""
    W = np.asarray(world_T_base_mm, dtype=float)
    reported = np.array([W @ kin.forward(qi) for qi in q_rad])
    Xi = invert_transform(np.asarray(flange_T_camera_mm, dtype=float))
    meas = np.array([Xi @ invert_transform(W @ arm.forward(qi)) @ world_T_target_mm for qi in q_rad])
    return reported, meas
