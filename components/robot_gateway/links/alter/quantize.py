"""ALTER's wire quantisation: a step (already clamped, in the controller's ALTER frame) as a
CORRECTION in 0.01 mm / 0.01 deg whose rounded values still respect the limits."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from humanpt.geometry.transforms import rotation_angle_rad, rotation_from_ypr_deg
from humanpt.robot_gateway.links.alter.messages import (
    DEG_PER_UNIT,
    NO_FLAGS,
    Correction,
    CorrectionFlags,
)
from humanpt.robot_gateway.safety import rotation_angle_deg, wire_rotation_deg
from humanpt.robot_gateway.safety import vector_norm as _norm

_QUANT_MM = 0.01  # wire unit of translation
_QUANT_DEG = 0.01  # wire unit of rotation


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
