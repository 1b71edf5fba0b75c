"""The gateway's safety arithmetic, pure numpy: per-cycle clamping, the workspace
envelope, frame changes and quantisation to the wire's fixed point.

Units: translations in mm, rotations as rotation vectors in radians (axis * angle);
frames are named (``world``, ``base`` = the controller's ALTER world, ``tool`` = flange).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from humanpt.alter import Correction, CorrectionFlags
from humanpt.alter.messages import DEG_PER_UNIT, NO_FLAGS
from humanpt.geometry.transforms import (
    matrix_from_rotvec,
    rotation_angle_rad,
    rotation_from_ypr_deg,
    ypr_deg_from_rotation,
)

_QUANT_MM = 0.01  # wire unit of translation
_QUANT_DEG = 0.01  # wire unit of rotation


def _norm(v: np.ndarray) -> float:
    """``np.linalg.norm(v)`` of a float vector, as it computes it (sqrt of the dot product
    of the raveled vector with itself), without its per-call overhead."""
    x = v.ravel(order="K")
    return math.sqrt(x.dot(x))


def safe_norm(v: np.ndarray) -> float:
    """The Euclidean norm of a finite vector without overflow in its squares (inf only when
    the norm itself is beyond the float range)."""
    big = float(np.max(np.abs(v))) if np.size(v) else 0.0
    if big == 0.0 or not math.isfinite(big):
        return big
    return big * _norm(np.asarray(v, dtype=float) / big)


def clamp_norm(v: np.ndarray, limit: float) -> tuple[np.ndarray, bool]:
    """(3,) ``v`` scaled down to norm ``limit`` if longer (direction kept); (v, clamped?).

    Safe for any finite ``v``: a step of 1e305 is clamped, not squared into inf and NaN."""
    v = np.asarray(v, dtype=float)
    with np.errstate(over="ignore"):
        n = _norm(v)
    if n <= limit:
        return v, False
    if math.isfinite(n):
        return v * (limit / n), True
    u = v / float(np.max(np.abs(v)))  # components within [-1, 1]: no overflow
    return u * (limit / _norm(u)), True


def clip_to_envelope(
    p_mm: np.ndarray, dp_mm: np.ndarray, lo_mm: np.ndarray, hi_mm: np.ndarray, repeats: int = 0
) -> tuple[np.ndarray, bool]:
    """The step ``dp_mm`` (3,) from ``p_mm`` (3,), cut so that p + dp stays in the box
    [lo, hi] (world mm). A flange already outside may move back in, never further out
    (per axis the box is widened to include p). ``repeats``: the robot may apply the step
    that many more times on its own (RSI with HOLDON on repeats the last relative
    correction for each late answer): then p + (1 + repeats) dp stays in the box, per axis
    the step being at most the room left / (1 + repeats). Returns (dp, clipped?)."""
    n = 1 + repeats
    p = np.asarray(p_mm, dtype=float)
    target = p + n * np.asarray(dp_mm, dtype=float)
    if all(a < t < b for a, t, b in zip(lo_mm, target.tolist(), hi_mm, strict=True)):
        return (target - p) / n, False  # well inside: what the clip below gives, quicker (n = 1: exact)
    lo = np.minimum(np.asarray(lo_mm, dtype=float), p)
    hi = np.maximum(np.asarray(hi_mm, dtype=float), p)
    clipped = np.clip(target, lo, hi)
    return (clipped - p) / n, bool(np.any(clipped != target))


def rotation_angle_deg(rv_rad: np.ndarray) -> float:
    return math.degrees(safe_norm(rv_rad))


def wire_rotation_deg(rv_rad: np.ndarray) -> np.ndarray:
    """Rotation vector -> the wire's (drx, dry, drz) degrees with dR = Rz(drz) Ry(dry) Rx(drx)."""
    drz, dry, drx = ypr_deg_from_rotation(matrix_from_rotvec(rv_rad), assume_valid=True)
    return np.array([drx, dry, drz])


def correction_angle_deg(c: Correction) -> float:
    """Rotation angle of a (quantised) correction, degrees."""
    return _angle_deg_cdeg(c.drx_cdeg, c.dry_cdeg, c.drz_cdeg)


@lru_cache(maxsize=4096)
def _angle_deg_cdeg(drx_cdeg: int, dry_cdeg: int, drz_cdeg: int) -> float:
    """Angle of Rz(drz) Ry(dry) Rx(drx), wire units in, degrees out. Cached: the
    corrections of a steady motion repeat the same few wire values."""
    drx, dry, drz = np.array([drx_cdeg, dry_cdeg, drz_cdeg], dtype=float) * DEG_PER_UNIT
    return float(np.degrees(rotation_angle_rad(rotation_from_ypr_deg([drz, dry, drx]))))


def quantize(
    echo_cycle: int,
    dp_mm: np.ndarray,
    rv_rad: np.ndarray,
    max_step_mm: float,
    max_step_deg: float,
    flags: CorrectionFlags = NO_FLAGS,
) -> Correction:
    """A Correction for ``dp_mm`` (3,) and ``rv_rad`` (3,) (already clamped, in the
    controller's ALTER frame) whose *quantised* values still respect the limits: rounding
    to 0.01 mm / 0.01 deg can add up to ~0.009 mm / deg, so a step at the limit that would
    poke out after rounding is shrunk by the smallest margin (0.005, 0.01, 0.02, 0.04 mm or
    deg) that keeps it in."""
    dp0 = np.asarray(dp_mm, dtype=float)
    rv0 = np.asarray(rv_rad, dtype=float)
    dp, rv = dp0, rv0
    for margin in (0.5, 1.0, 2.0, 4.0, None):
        c = Correction.from_mm_deg(echo_cycle, dp, wire_rotation_deg(rv), flags)
        over_t = _norm(c.translation_mm) > max_step_mm + 1e-9
        over_r = correction_angle_deg(c) > max_step_deg + 1e-9
        if not (over_t or over_r):
            return c
        if margin is None:
            break
        if over_t:
            dp = dp0 * max(0.0, (max_step_mm - margin * _QUANT_MM) / _norm(dp0))
        if over_r:
            rv = rv0 * max(0.0, (max_step_deg - margin * _QUANT_DEG) / rotation_angle_deg(rv0))
    return Correction.from_mm_deg(echo_cycle, np.zeros(3), np.zeros(3), flags)  # not reached
