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


def seam_command(seam, speed_mm_s: float, flange_T_tool_x, max_points: int = MAX_PLAYBACK_POINTS) -> dict:
    """The ``playback`` command's arguments for a seam (:class:`humanpt.seam.fit.Seam`):
    re-timed at ``speed_mm_s`` with the tool ``flange_T_tool_x`` (x, y, z mm, Z-Y-X deg) so
    that the flange stays within :data:`PLAYBACK_LIMIT_SHARE` of the robot's limits (a
    corner's turn on the spot at a rate the flange can swing), then thinned to
    ``max_points`` (:func:`thin`): ``{"points": (N, 6) list, "times_s": (N,) list}`` from 0.
    The one way a seam becomes a playback (``humanpt path play``, the console, the twin's
    job).  RetimeError, PlaybackError: what cannot be played, and why."""
    from humanpt.seam.retime import RetimeConfig, retime

    cfg = RetimeConfig(speed_mm_s=speed_mm_s, flange_T_tool_x=tuple(float(v) for v in flange_T_tool_x),
                       limit_share=PLAYBACK_LIMIT_SHARE)
    timed = retime(seam, cfg)
    x, t = thin(timed.x, timed.t_s, max_points)
    return {"points": np.round(x, 4).tolist(), "times_s": np.round(t - t[0], 6).tolist()}
