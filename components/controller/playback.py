"""A playback's points, checked and bounded: what the controller's ``playback`` command
carries, and what its sender prepares (issue 29, items 4 and 9).

The controller runs on the robot link's cycle (SCHED_FIFO, 28 ms for ALTER): its work for
one command must stay well inside a cycle.  So a command is bounded before it is parsed
(:data:`MAX_ARGS_CHARS`), carries at most :data:`MAX_PLAYBACK_POINTS` tool poses, and is
checked with array operations (:func:`check_points`, :func:`check_times`,
:func:`envelope_refusal`); the heavy work (reading a seam, re-timing it, thinning its
samples to the limit within a tolerance: :func:`thin`) is the sender's (``humanpt path
play``, ``humanpt console playback``), which refuses what does not fit before sending.

Every point of a playback must put the flange (the tool pose times the inverse of
``flange_T_tool``) inside the robot gateway's workspace envelope, an axis-aligned box in
the world frame: the first point outside is named with the limit it crosses.  Pure: no
clock, no I/O; mm and degrees at this edge.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from humanpt.geometry.transforms import invert_transform, rotvec_from_matrix, transform_from_x
from humanpt.runtime.config import ConfigError, Deg, Mm

# The largest playback the controller takes: its handling (parse, check, prepare) of a
# command this size measures 4-6 ms on the 2-core test machine (tests/controller/
# test_playback_limits.py prints it), well inside one 28 ms ALTER cycle.  A re-timed
# seam sampled every 28 ms fits 2000 points for 56 s; longer ones are thinned by
# their sender (linear in between: the controller's carrot interpolates), within
# THIN_TOLERANCE_MM of every sample, or refused.
MAX_PLAYBACK_POINTS = 2000
# The command's JSON text is bounded before it is parsed: 2000 points of 6 numbers and
# their times with up to 20 characters per number, with room to spare.
MAX_ARGS_CHARS = 400_000
# How far a thinned playback may pass from a re-timed sample it leaves out (mm, and the
# same figure in degrees for the orientation).
THIN_TOLERANCE_MM = 0.05
# The share of the robot's speed and rate limits a played seam's timing may use for the
# flange's own motion (humanpt.seam.retime's limit_share); the rest is the servo's, for its
# corrections: a plan at 100 % would saturate the step on every correction.
PLAYBACK_LIMIT_SHARE = 0.9
# The ranges of the command's numbers (runtime.config's Mm and Deg, symmetric; the times' own).
POSE_LIMITS = (Mm.__metadata__[0].hi,) * 3 + (Deg.__metadata__[0].hi,) * 3
POSE_UNITS = ("mm", "mm", "mm", "deg", "deg", "deg")
MAX_TIME_S = 1e6
AXES = "xyz"


class PlaybackError(ValueError):
    """A playback that cannot be sent or played; the message says which point and why."""


def check_points(points, where: str = "points", booleans: bool = True) -> np.ndarray:
    """(N, 6) float array of tool poses (x, y, z mm, psi, theta, phi deg) from a JSON
    list of lists; :class:`ConfigError` naming the first bad element (``points[3][5]``):
    not six numbers, not finite, outside +-5000 mm / +-360 deg, or more than
    :data:`MAX_PLAYBACK_POINTS` points.  Vectorised: the cost is numpy's conversion
    (``booleans=False``: the JSON text had no true or false, which numpy would take for 1
    and 0; else a per-element look for them)."""
    if not isinstance(points, (list, tuple)):
        raise ConfigError(f"{where}: expected a list of [x, y, z, psi, theta, phi], got {type(points).__name__}")
    if len(points) > MAX_PLAYBACK_POINTS:
        raise ConfigError(f"{where}: {len(points)} points; the controller takes at most {MAX_PLAYBACK_POINTS}")
    x = _numbers(points)
    if x is None or not (x.ndim == 2 and x.shape[1] == 6 or x.size == 0):
        _first_malformed(points, where)  # raises, naming the element
    x = x.reshape(-1, 6)
    if booleans:
        _no_booleans(points, where)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(x) | (np.abs(x) > np.asarray(POSE_LIMITS))
    if bad.any():
        i, j = np.argwhere(bad)[0]
        v = x[i, j]
        if not math.isfinite(v):
            raise ConfigError(f"{where}[{i}][{j}]: expected a finite number, got {v!r}")
        raise ConfigError(f"{where}[{i}][{j}]: {v!r} is outside its range [{-POSE_LIMITS[j]:g}, "
                          f"{POSE_LIMITS[j]:g}] {POSE_UNITS[j]}")
    return x


def _numbers(values) -> np.ndarray | None:
    """A float array of nested lists of numbers, None when they are not (numpy would take
    "1" for 1.0 if asked for floats: its own inference says what the elements are)."""
    try:
        a = np.array(values)
    except (TypeError, ValueError):  # ragged
        return None
    return a.astype(float) if a.dtype.kind in "fiu" or a.size == 0 else None


def _first_malformed(points: Sequence, where: str) -> None:
    """Name the first element that is not a row of six numbers (only called on failure)."""
    for i, p in enumerate(points):
        if not isinstance(p, (list, tuple)):
            raise ConfigError(f"{where}[{i}]: expected a list of 6 values, got {type(p).__name__} {p!r}")
        if len(p) != 6:
            raise ConfigError(f"{where}[{i}]: expected 6 values, got {len(p)}")
        for j, v in enumerate(p):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ConfigError(f"{where}[{i}][{j}]: expected a number, got {v!r}")
    raise ConfigError(f"{where}: expected a list of [x, y, z, psi, theta, phi]")


def _no_booleans(rows: Sequence, where: str) -> None:
    """JSON true/false are not numbers (numpy would take them as 1 and 0)."""
    for i, p in enumerate(rows):
        if isinstance(p, bool) or (isinstance(p, (list, tuple)) and any(isinstance(v, bool) for v in p)):
            raise ConfigError(f"{where}[{i}]: expected numbers, got {p!r}")


def check_times(times, n: int, where: str = "times_s", booleans: bool = True) -> np.ndarray:
    """(N,) float array of a playback's times (s from any start): one per point, finite,
    within [0, 1e6] s, never decreasing; :class:`ConfigError` naming the first bad one
    (``booleans`` as in :func:`check_points`)."""
    if not isinstance(times, (list, tuple)):
        raise ConfigError(f"{where}: expected a list of times, got {type(times).__name__}")
    if len(times) != n:
        raise ConfigError(f"{where}: {len(times)} times for {n} points: one time per point")
    t = _numbers(times)
    if t is None or t.ndim != 1 or (booleans and any(isinstance(v, bool) for v in times)):
        bad = next((i for i, v in enumerate(times) if isinstance(v, bool) or not isinstance(v, (int, float))), 0)
        raise ConfigError(f"{where}[{bad}]: expected a number, got {times[bad]!r}")
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(t) | (t < 0.0) | (t > MAX_TIME_S)
    if bad.any():
        i = int(np.argmax(bad))
        raise ConfigError(f"{where}[{i}]: {t[i]!r} is outside its range [0, {MAX_TIME_S:g}] s")
    back = np.diff(t) < 0
    if back.any():
        i = int(np.argmax(back)) + 1
        raise ConfigError(f"{where}[{i}]: {t[i]:g} s is before the point before it ({t[i - 1]:g} s): "
                          "the times must be never decreasing")
    return t


def feed_forward(world_T_now: np.ndarray, world_T_next: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The velocity (3,) and angular velocity (3,) (world frame, per second; the
    translation's unit) that carry a frame from ``world_T_now`` to ``world_T_next`` (4, 4)
    in ``dt_s``, as a robot applies a step (``R' = exp(w dt) R``, ``t' = t + v dt``,
    :func:`humanpt.geometry.transforms.apply_step`): what a playback feeds forward."""
    v = (world_T_next[:3, 3] - world_T_now[:3, 3]) / dt_s
    w = rotvec_from_matrix(world_T_next[:3, :3] @ world_T_now[:3, :3].T, assume_valid=True) / dt_s
    return v, w


def flange_positions_mm(points_mm_deg: np.ndarray, flange_T_tool_mm: np.ndarray) -> np.ndarray:
    """(N, 3) world positions of the flange (mm) when the tool is at each pose (N, 6)."""
    world_T_tool = transform_from_x(np.asarray(points_mm_deg, dtype=float).reshape(-1, 6))
    return (world_T_tool @ invert_transform(flange_T_tool_mm))[:, :3, 3]


def envelope_refusal(points_mm_deg: np.ndarray, flange_T_tool_mm: np.ndarray, envelope_min_mm, envelope_max_mm,
                     owner: str = "the workspace envelope", flange_p_mm: np.ndarray | None = None) -> str | None:
    """One line naming the first point whose flange lies outside the box
    [envelope_min_mm, envelope_max_mm] (world, mm) and the limit it crosses; None when
    every point is inside.  ``flange_p_mm`` (N, 3): the flange positions when the caller
    has them (:func:`flange_positions_mm`)."""
    p = flange_positions_mm(points_mm_deg, flange_T_tool_mm) if flange_p_mm is None else flange_p_mm
    lo, hi = np.asarray(envelope_min_mm, dtype=float), np.asarray(envelope_max_mm, dtype=float)
    below, above = p < lo, p > hi
    out = (below | above).any(axis=1)
    if not out.any():
        return None
    i = int(np.argmax(out))
    j = int(np.argmax(below[i] | above[i]))
    side, limit = ("below", lo[j]) if below[i, j] else ("above", hi[j])
    pose = np.asarray(points_mm_deg, dtype=float).reshape(-1, 6)[i]
    return (f"point {i} of {len(p)} (tool at {_fmt(pose[:3])} mm) puts the flange at {_fmt(p[i])} mm: "
            f"{AXES[j]} {p[i, j]:.1f} is {side} {owner}'s {'min' if side == 'below' else 'max'} {limit:g} mm "
            f"({_fmt(lo)}..{_fmt(hi)} mm)")


def _fmt(v) -> str:
    return "[" + ", ".join(f"{float(a):.1f}" for a in v) + "]"


def thin(points_mm_deg: np.ndarray, times_s: np.ndarray, max_points: int = MAX_PLAYBACK_POINTS,
         tolerance: float = THIN_TOLERANCE_MM) -> tuple[np.ndarray, np.ndarray]:
    """Every k-th sample of a timed playback (ends kept), the least k that leaves at most
    ``max_points``, if the pose interpolated linearly in time between the kept ones passes
    within ``tolerance`` (mm, and deg for the angles) of every sample left out;
    :class:`PlaybackError` otherwise.  Vectorised, O(N)."""
    x = np.asarray(points_mm_deg, dtype=float).reshape(-1, 6)
    t = np.asarray(times_s, dtype=float).reshape(-1)
    n = len(x)
    if n <= max_points:
        return x, t
    k = int(math.ceil((n - 1) / (max_points - 1)))
    keep = np.unique(np.r_[np.arange(0, n, k), n - 1])
    while len(keep) > max_points:  # (the last interval may be short)
        k += 1
        keep = np.unique(np.r_[np.arange(0, n, k), n - 1])
    # Each sample against the straight line (in time) between its kept neighbours.
    right = np.clip(np.searchsorted(keep, np.arange(n), side="left"), 1, len(keep) - 1)
    a, b = keep[right - 1], keep[right]
    span = t[b] - t[a]
    f = np.where(span > 0, (t - t[a]) / np.where(span > 0, span, 1.0), 0.0)[:, None]
    angles = x[b, 3:] - x[a, 3:]
    angles = (angles + 180.0) % 360.0 - 180.0  # the short way round
    interp = np.column_stack([x[a, :3] + f * (x[b, :3] - x[a, :3]), x[a, 3:] + f * angles])
    d = x - interp
    d[:, 3:] = (d[:, 3:] + 180.0) % 360.0 - 180.0
    err_mm = float(np.linalg.norm(d[:, :3], axis=1).max())
    err_deg = float(np.abs(d[:, 3:]).max())
    if err_mm > tolerance or err_deg > tolerance:
        raise PlaybackError(
            f"{n} samples ({t[-1] - t[0]:.1f} s) do not fit the controller's {max_points} points: every "
            f"{k}th sample passes {err_mm:.3f} mm / {err_deg:.3f} deg from the others (tolerance "
            f"{tolerance:g}); play the seam in parts or faster")
    return x[keep], t[keep]


# On an arm with kinematics (RobotArm): the most a seam's timing may be slowed down where a
# joint would turn faster than its share of the joint speed limit; a seam that needs more
# (it passes within a hair of the wrist singularity) is refused.
MAX_SLOWDOWN = 8.0
# |sin q5| below this (2 deg) counts as the wrist singularity when a plan is refused: the
# reason names it (joints 4 and 6 coaxial).
WRIST_SINGULAR_SIN = math.sin(math.radians(2.0))


@dataclass(frozen=True)
class RobotArm:
    """What a playback needs of an arm with kinematics to plan on it (a Puma over ALTER):
    its model (``kinematics``: :class:`humanpt.geometry.puma.PumaKinematics`), where it is
    mounted (``world_T_base_mm`` (4, 4)), its joints now (``joints_rad`` (6,)), the joint
    speed limit its controller faults beyond and its cycle; the flange's limits as the
    gateway's (mm/s, deg/s)."""

    kinematics: Any
    world_T_base_mm: np.ndarray
    joints_rad: np.ndarray
    max_joint_speed_deg_s: float = 250.0
    cycle_s: float = 0.028
    max_speed_mm_s: float = 100.0
    max_angular_deg_s: float = 60.0
    # The arm as calibrated (issue 32.4): its forward kinematics (``forward(q_rad)`` ->
    # base_T_flange mm at the encoders' angles, e.g. the rig's ``[arm]``:
    # ``Rig.arm.true_arm()``), or None: the nominal model is taken as the arm.  With it the
    # seam's poses are where the torch must truly go, and each is sent as the pose the
    # controller's nominal model reaches with the joints that put the calibrated arm there
    # (:func:`command_poses`).
    true_arm: Any = None


@dataclass(frozen=True)
class ArmPlan:
    """A playback planned on an arm: ``x`` (N, 6) tool poses mm/deg at ``t_s`` (N,), the
    approach's first ``approach`` samples (from the arm's pose now, in joint space) then
    the seam; ``joints_rad`` (N, 6) what the arm's joints do; ``slowdown`` the most the
    seam's timing was stretched for a joint's rate (1: not at all); ``min_wrist_deg``
    the least |q5| along the plan."""

    x: np.ndarray
    t_s: np.ndarray
    joints_rad: np.ndarray
    approach: int
    slowdown: float
    min_wrist_deg: float

    @property
    def max_joint_speed_deg_s(self) -> float:
        dq = np.abs(np.diff(self.joints_rad, axis=0)).max(axis=1)
        dt = np.diff(self.t_s)
        ok = dt > 0
        return float(np.degrees(dq[ok] / dt[ok]).max()) if ok.any() else 0.0


def _smooth_stretch(f: np.ndarray, window: int) -> np.ndarray:
    """A stretch factor per interval (>= 1) that is never below ``f`` and changes gradually
    (a running maximum over ``window`` intervals, then a running mean over half of it)."""
    from scipy.ndimage import maximum_filter1d, uniform_filter1d

    if len(f) == 0:
        return f
    m = maximum_filter1d(np.maximum(f, 1.0), size=2 * window + 1, mode="nearest")
    return np.maximum(uniform_filter1d(m, size=window + 1, mode="nearest"), np.maximum(f, 1.0))


def _seam_on_arm(base_T_flange: np.ndarray, q0: np.ndarray, dt: np.ndarray, arm: RobotArm,
                 pose_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray] | str:
    """The joints (N, 6) along the seam from the branch ``q0`` and the stretch per interval
    (N-1,) that keeps every joint within its share of the limit, or why not (one line)."""
    from humanpt.geometry.puma import UnreachableError, follow, wrist_sin

    try:
        q = follow(arm.kinematics, base_T_flange, q0)
    except UnreachableError as e:
        i = int(str(e).split()[1]) if str(e).startswith("pose ") else 0
        return f"point {i} (tool at {_fmt(pose_mm[i, :3])} mm) is out of the arm's reach at this mounting ({e})"
    s5 = wrist_sin(q)
    flip = np.nonzero(s5[1:] * s5[:-1] < 0)[0]
    if len(flip) or (np.abs(s5) < WRIST_SINGULAR_SIN).any():
        i = int(flip[0] + 1) if len(flip) else int(np.argmin(np.abs(s5)))
        return (f"the seam passes through the wrist singularity at point {i} (tool at {_fmt(pose_mm[i, :3])} mm, "
                f"q5 {np.degrees(q[i, 4]):.1f} deg: joints 4 and 6 coaxial)")
    limit = PLAYBACK_LIMIT_SHARE * math.radians(arm.max_joint_speed_deg_s)
    dq = np.abs(np.diff(q, axis=0)).max(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(dt > 0, dq / (limit * np.where(dt > 0, dt, 1.0)), np.where(dq > 1e-12, np.inf, 0.0))
    if len(f) and f.max() > MAX_SLOWDOWN:
        i = int(np.argmax(f)) + 1
        j = int(np.argmax(np.abs(q[i] - q[i - 1])))
        near = (f"within {np.degrees(abs(np.arcsin(s5[i]))):.1f} deg of the wrist singularity "
                if abs(s5[i]) < 0.2 else "")
        return (f"at point {i} (tool at {_fmt(pose_mm[i, :3])} mm) {near}joint {j + 1} would turn "
                f"{f[i - 1]:.0f} times faster than {PLAYBACK_LIMIT_SHARE:.0%} of its "
                f"{arm.max_joint_speed_deg_s:g} deg/s (the most a seam is slowed down is {MAX_SLOWDOWN:g} times)")
    return q, f


# command_poses: Newton steps until the calibrated arm is this close to the desired pose
# (mm, and rad for the rotation); a few steps suffice (the errors are a millimetre).
COMMAND_TOL_MM, COMMAND_TOL_RAD, COMMAND_MAX_STEPS = 1e-6, 1e-9, 20


def command_poses(kin, true_arm, base_T_flange_desired: np.ndarray, q_rad: np.ndarray,
                  ) -> tuple[np.ndarray, np.ndarray]:
    """For flange poses (N, 4, 4) mm where the physical arm must be, the joints (N, 6) rad
    that put the calibrated ``true_arm`` there and the poses (N, 4, 4) the controller's
    nominal model ``kin`` gives for those joints: what to command.  ``q_rad`` (N, 6): the
    nominal inverse kinematics of the desired poses (the branch the arm plays on), where
    Newton's steps (the nominal Jacobian, least squares) start.  Raises UnreachableError
    when a pose does not converge (a singular wrist)."""
    from humanpt.geometry.puma import UnreachableError

    T_d = np.asarray(base_T_flange_desired, dtype=float).reshape(-1, 4, 4)
    q_out = np.array(q_rad, dtype=float).reshape(-1, 6)
    cmd = np.empty_like(T_d)
    for i, (Td, q) in enumerate(zip(T_d, q_out, strict=True)):
        for _ in range(COMMAND_MAX_STEPS):
            T = true_arm.forward(q)
            e = np.r_[Td[:3, 3] - T[:3, 3], rotvec_from_matrix(Td[:3, :3] @ T[:3, :3].T, assume_valid=True)]
            if np.abs(e[:3]).max() < COMMAND_TOL_MM and np.abs(e[3:]).max() < COMMAND_TOL_RAD:
                break
            q = q + np.linalg.lstsq(kin.jacobian(q), e, rcond=None)[0]
        else:
            raise UnreachableError(f"pose {i} of {len(T_d)}: the calibrated arm does not converge there "
                                   f"({np.abs(e[:3]).max():.2g} mm off after {COMMAND_MAX_STEPS} steps)")
        q_out[i] = q
        cmd[i] = kin.forward(q)
    return q_out, cmd


def _approach(arm: RobotArm, q_from: np.ndarray, q_to: np.ndarray, flange_T_tool_mm: np.ndarray,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An approach in joint space from ``q_from`` to ``q_to`` (6,) rad: every joint moves
    on a straight line with a cosine profile (at rest at both ends), its duration the least
    that keeps the joints, the flange's speed and its rotation within
    :data:`PLAYBACK_LIMIT_SHARE` of the limits.  (tool poses (K, 6) mm/deg, times (K,),
    joints (K, 6)), sampled every cycle, ending at ``q_to``."""
    from humanpt.geometry.transforms import x_from_transform

    kin = arm.kinematics
    s = np.linspace(0.0, 1.0, 201)
    q = q_from + s[:, None] * (q_to - q_from)
    T = np.array([kin.forward(qi) for qi in q])
    ds = s[1] - s[0]
    dp = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1).max() / ds
    dr = max((float(np.linalg.norm(rotvec_from_matrix(T[i + 1, :3, :3] @ T[i, :3, :3].T, assume_valid=True)))
              for i in range(len(T) - 1)), default=0.0) / ds
    dq = float(np.abs(q_to - q_from).max())
    peak = math.pi / 2  # the cosine profile's peak ds/dtau over its mean
    share = PLAYBACK_LIMIT_SHARE
    duration = peak * max(dp / (share * arm.max_speed_mm_s), dr / (share * math.radians(arm.max_angular_deg_s)),
                          dq / (share * math.radians(arm.max_joint_speed_deg_s)), 4 * arm.cycle_s)
    n = int(math.ceil(duration / arm.cycle_s))
    t = np.arange(n + 1) * arm.cycle_s
    sp = 0.5 - 0.5 * np.cos(math.pi * t / t[-1])
    qs = q_from + sp[:, None] * (q_to - q_from)
    world_T_tool = np.array([arm.world_T_base_mm @ kin.forward(qi) @ flange_T_tool_mm for qi in qs])
    return x_from_transform(world_T_tool), t, qs


def plan_on_arm(x_mm_deg: np.ndarray, t_s: np.ndarray, flange_T_tool_mm: np.ndarray, arm: RobotArm) -> ArmPlan:
    """A timed playback (tool poses (N, 6) mm/deg at ``t_s``) planned on ``arm`` (issue 33):

    * the seam's first pose is reached on the in-limits branch whose wrist is on the same
      side of its singularity as now (q5 keeps its sign: the approach never crosses
      q5 = 0), in the same arm and elbow configuration when there is one, the closest in
      joint space; along the seam the arm's joints are those its
      controller will take (the closest branch, cycle by cycle: ``geometry.puma.follow``);
    * the seam stays in Cartesian space; where a joint would turn faster than
      :data:`PLAYBACK_LIMIT_SHARE` of its limit, the timing is stretched there (gradually,
      only slower: the path is the same), by at most :data:`MAX_SLOWDOWN`;
    * the approach, from the arm's joints now, is a straight line in joint space (so the
      wrist stays on its side of the singularity), within the share of every limit;
    * what cannot be played is refused with the reason (:class:`PlaybackError`): a point
      out of reach at this mounting, a seam through the wrist singularity (q5 changing
      sign, or |q5| under 2 deg) or one that would need a joint faster than the most
      slow-down allows, on every branch;
    * with ``arm.true_arm`` (the arm as calibrated) the seam's poses are where the torch
      must truly go: each is commanded as the pose the controller's nominal model reaches
      with the joints that put the calibrated arm there (:func:`command_poses`), and the
      plan's ``x`` along the seam are those commands.

    Pure: no clock, no I/O."""
    from humanpt.geometry.puma import UnreachableError, follow, wrist_sin
    from humanpt.geometry.transforms import x_from_transform

    x = np.asarray(x_mm_deg, dtype=float).reshape(-1, 6)
    t = np.asarray(t_s, dtype=float).reshape(-1)
    base_T_world = invert_transform(np.asarray(arm.world_T_base_mm, dtype=float))
    tool_T_flange = invert_transform(np.asarray(flange_T_tool_mm, dtype=float))
    base_T_flange = base_T_world @ transform_from_x(x) @ tool_T_flange
    kin, q_now = arm.kinematics, np.asarray(arm.joints_rad, dtype=float)
    s_now = float(wrist_sin(q_now))
    sols = [s for s in kin.inverse_all(base_T_flange[0], q_now) if s.within_limits]
    if not sols:
        raise PlaybackError(f"point 0 (tool at {_fmt(x[0, :3])} mm) is out of the arm's reach at this mounting "
                            f"(no inverse-kinematics branch within the joint limits)")
    # The same side of the wrist singularity as now first (the approach then never crosses
    # it), each side the closest first.

    # The arm and elbow the arm is in now (a joint-space approach to another crosses the
    # shoulder or elbow singularity on the way).
    now_arm = next((s.config[:2] for s in kin.inverse_all(kin.forward(q_now), q_now)
                    if s.within_limits and np.allclose(s.q_rad, q_now, atol=1e-6)), None)

    def order(sol) -> tuple[bool, bool, float]:
        crosses = float(wrist_sin(sol.q_rad)) * s_now < 0 and abs(s_now) > WRIST_SINGULAR_SIN
        return crosses, sol.config[:2] != now_arm, float(np.linalg.norm(sol.q_rad - q_now))

    sols.sort(key=order)
    dt = np.diff(t)
    reasons = []
    for sol in sols:
        q0 = sol.q_rad
        if abs(float(wrist_sin(q0))) < WRIST_SINGULAR_SIN:
            reasons.append(f"{'/'.join(sol.config)}: the seam starts at the wrist singularity")
            continue
        if float(wrist_sin(q0)) * s_now < 0 and abs(s_now) > WRIST_SINGULAR_SIN:
            reasons.append(f"{'/'.join(sol.config)}: the approach would cross the wrist singularity")
            continue
        seam_T, x_seam = base_T_flange, x
        if arm.true_arm is not None:  # the calibrated arm: command what puts it on the seam
            try:
                q_cal, seam_T = command_poses(kin, arm.true_arm, base_T_flange, follow(kin, base_T_flange, q0))
            except UnreachableError:
                q_cal = None  # _seam_on_arm names the point
            if q_cal is not None:
                x_seam = x_from_transform(arm.world_T_base_mm @ seam_T @ flange_T_tool_mm)
                q0 = q_cal[0]
        got = _seam_on_arm(seam_T, q0, dt, arm, x)
        if isinstance(got, str):
            reasons.append(f"{'/'.join(sol.config)}: {got}")
            continue
        q_seam, f = got
        xa, ta, qa = _approach(arm, q_now, q0, flange_T_tool_mm)
        # The arm's controller takes the approach's poses to the same joints (closest branch).
        try:
            qf = follow(kin, base_T_world @ transform_from_x(xa) @ tool_T_flange, q_now)
        except UnreachableError as e:
            reasons.append(f"{'/'.join(sol.config)}: the approach leaves the reach ({e})")
            continue
        if np.abs(qf - qa).max() > math.radians(0.5):
            reasons.append(f"{'/'.join(sol.config)}: the approach's joints are not the controller's")
            continue
        stretch = _smooth_stretch(f, max(1, int(round(0.5 / arm.cycle_s))))
        t_seam = np.r_[0.0, np.cumsum(dt * stretch)] if len(dt) else np.zeros(1)
        x_all = np.vstack([xa[:-1], x_seam])
        t_all = np.r_[ta[:-1], ta[-1] + t_seam]
        q_all = np.vstack([qa[:-1], q_seam])
        return ArmPlan(x_all, t_all, q_all, len(xa) - 1, float(stretch.max()) if len(stretch) else 1.0,
                       float(np.degrees(np.abs(np.arcsin(np.clip(wrist_sin(q_all), -1, 1)))).min()))
    raise PlaybackError("cannot be played on this arm at this mounting: " + "; ".join(reasons))


# How far a thinned approach (planned in joint space, through free space) may pass from its
# samples (mm, and deg): the controller's carrot goes straight between the kept ones.
APPROACH_TOLERANCE_MM = 0.5


def thin_within(points_mm_deg: np.ndarray, times_s: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """The fewest samples :func:`thin` keeps within ``tolerance`` (every 2nd, 4th, ...
    sample while it holds)."""
    x, t = np.asarray(points_mm_deg, dtype=float).reshape(-1, 6), np.asarray(times_s, dtype=float).reshape(-1)
    best = (x, t)
    k = 2
    while len(x) > 2 and (len(x) - 1) // k >= 1:
        try:
            best = thin(x, t, max(2, (len(x) - 1) // k + 1), tolerance)
        except PlaybackError:
            break
        k *= 2
    return best


def seam_command(seam, speed_mm_s: float, flange_T_tool_x, max_points: int = MAX_PLAYBACK_POINTS,
                 arm: RobotArm | None = None) -> dict:
    """The ``playback`` command's arguments for a seam (:class:`humanpt.seam.fit.Seam`):
    re-timed at ``speed_mm_s`` with the tool ``flange_T_tool_x`` (x, y, z mm, Z-Y-X deg) so
    that the flange stays within :data:`PLAYBACK_LIMIT_SHARE` of the robot's limits (a
    corner's turn on the spot at a rate the flange can swing), then thinned to
    ``max_points`` (:func:`thin`): ``{"points": (N, 6) list, "times_s": (N,) list}`` from 0.
    The one way a seam becomes a playback (``humanpt path play``, the console, the twin's
    job).  ``arm``: the arm it will play on (a Puma): planned on it (:func:`plan_on_arm`: a
    joint-space approach from its joints now, the seam slowed where a joint would be too
    fast, refused when the arm cannot play it).  RetimeError, PlaybackError: what cannot be
    played, and why."""
    from humanpt.seam.retime import RetimeConfig, retime

    cfg = RetimeConfig(speed_mm_s=speed_mm_s, flange_T_tool_x=tuple(float(v) for v in flange_T_tool_x),
                       limit_share=PLAYBACK_LIMIT_SHARE)
    timed = retime(seam, cfg)
    if arm is None:
        x, t = thin(timed.x, timed.t_s, max_points)
    else:
        plan = plan_on_arm(timed.x, timed.t_s, transform_from_x(np.asarray(flange_T_tool_x, dtype=float)), arm)
        # The approach (free space, away from every singularity) within APPROACH_TOLERANCE_MM,
        # the seam within THIN_TOLERANCE_MM in what is left of the points.
        k = plan.approach
        xa, ta = thin_within(plan.x[:k + 1], plan.t_s[:k + 1], APPROACH_TOLERANCE_MM)
        xs, ts = thin(plan.x[k:], plan.t_s[k:], max_points - (len(xa) - 1))
        x, t = np.vstack([xa[:-1], xs]), np.r_[ta[:-1], ts]
    return {"points": np.round(x, 4).tolist(), "times_s": np.round(t - t[0], 6).tolist()}
