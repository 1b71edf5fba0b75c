"""The gateway's safety arithmetic, pure numpy: per-cycle clamping, the workspace
envelope, rotation vectors as the wires' Z-Y-X degrees (each link quantises to its own
wire within the limits: ``links/alter/quantize.py``, ``links/rsi/protocol.py``).

Units: translations in mm, rotations as rotation vectors in radians (axis * angle);
frames are named (``world``, ``base`` = the controller's ALTER world, ``tool`` = flange).
"""

from __future__ import annotations

import math

import numpy as np

from humanpt.geometry.transforms import matrix_from_rotvec, ypr_deg_from_rotation


def vector_norm(v: np.ndarray) -> float:
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
    return big * vector_norm(np.asarray(v, dtype=float) / big)


def clamp_norm(v: np.ndarray, limit: float) -> tuple[np.ndarray, bool]:
    """(3,) ``v`` scaled down to norm ``limit`` if longer (direction kept); (v, clamped?).

    Safe for any finite ``v``: a step of 1e305 is clamped, not squared into inf and NaN."""
    v = np.asarray(v, dtype=float)
    with np.errstate(over="ignore"):
        n = vector_norm(v)
    if n <= limit:
        return v, False
    if math.isfinite(n):
        return v * (limit / n), True
    u = v / float(np.max(np.abs(v)))  # components within [-1, 1]: no overflow
    return u * (limit / vector_norm(u)), True


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
