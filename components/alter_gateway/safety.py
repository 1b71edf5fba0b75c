"""The gateway's safety arithmetic, pure numpy: per-cycle clamping, the workspace
envelope, frame changes and quantisation to the wire's fixed point.

Units: translations in mm, rotations as rotation vectors in radians (axis * angle);
frames are named (``world``, ``base`` = the controller's ALTER world, ``tool`` = flange).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from humanpt.alter import Correction, CorrectionFlags
from humanpt.alter.messages import NO_FLAGS

_QUANT_MM = 0.01  # wire unit of translation
_QUANT_DEG = 0.01  # wire unit of rotation


def clamp_norm(v: np.ndarray, limit: float) -> tuple[np.ndarray, bool]:
    """(3,) ``v`` scaled down to norm ``limit`` if longer (direction kept); (v, clamped?)."""
    v = np.asarray(v, dtype=float)
    n = float(np.linalg.norm(v))
    if n <= limit:
        return v, False
    return v * (limit / n), True


def clip_to_envelope(
    p_mm: np.ndarray, dp_mm: np.ndarray, lo_mm: np.ndarray, hi_mm: np.ndarray
) -> tuple[np.ndarray, bool]:
    """The step ``dp_mm`` (3,) from ``p_mm`` (3,), cut so that p + dp stays in the box
    [lo, hi] (world mm). A flange already outside may move back in, never further out
    (per axis the box is widened to include p). Returns (dp, clipped?)."""
    p = np.asarray(p_mm, dtype=float)
    target = p + np.asarray(dp_mm, dtype=float)
    lo = np.minimum(np.asarray(lo_mm, dtype=float), p)
    hi = np.maximum(np.asarray(hi_mm, dtype=float), p)
    clipped = np.clip(target, lo, hi)
    return clipped - p, bool(np.any(clipped != target))


def rotation_angle_deg(rv_rad: np.ndarray) -> float:
    return float(np.degrees(np.linalg.norm(rv_rad)))


def wire_rotation_deg(rv_rad: np.ndarray) -> np.ndarray:
    """Rotation vector -> the wire's (drx, dry, drz) degrees with dR = Rz(drz) Ry(dry) Rx(drx)."""
    drz, dry, drx = Rotation.from_rotvec(np.asarray(rv_rad, dtype=float)).as_euler(
        "ZYX", degrees=True
    )
    return np.array([drx, dry, drz])


def correction_angle_deg(c: Correction) -> float:
    """Rotation angle of a (quantised) correction, degrees."""
    drx, dry, drz = c.rotation_deg
    return float(np.degrees(Rotation.from_euler("ZYX", [drz, dry, drx], degrees=True).magnitude()))


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
    to 0.01 mm / 0.01 deg can add up to ~0.009 mm / deg, so a step at the limit is
    shrunk by that much before rounding when it would otherwise poke out."""
    dp = np.asarray(dp_mm, dtype=float)
    rv = np.asarray(rv_rad, dtype=float)
    for _ in range(4):
        c = Correction.from_mm_deg(echo_cycle, dp, wire_rotation_deg(rv), flags)
        over_t = float(np.linalg.norm(c.translation_mm)) - max_step_mm
        over_r = correction_angle_deg(c) - max_step_deg
        if over_t <= 1e-9 and over_r <= 1e-9:
            return c
        if over_t > 1e-9:
            n = float(np.linalg.norm(dp))
            dp = dp * max(0.0, (max_step_mm - 2 * _QUANT_MM) / n)
        if over_r > 1e-9:
            n = rotation_angle_deg(rv)
            rv = rv * max(0.0, (max_step_deg - 2 * _QUANT_DEG) / n)
    return Correction.from_mm_deg(
        echo_cycle, np.zeros(3), np.zeros(3), flags
    )  # never reached in practice
