"""What the gateway must put on the wire, worked out independently of its own safety code.

The rules come from the stated limits and the wire format, not from the gateway's
``clamp_norm`` / ``quantize``:

* per cycle, a translation step is at most ``max_speed_mm_s`` x the cycle time and a
  rotation at most ``max_angular_speed_deg_s`` x the cycle time, clamped by norm / by
  angle with the direction kept (components/robot_gateway/README.md, config docs);
* the CORRECTION message carries dx, dy, dz in 0.01 mm and drx, dry, drz in 0.01 deg
  with dR = Rz(drz) Ry(dry) Rx(drx) (components/alter/PROTOCOL.md);
* the limits hold after rounding: a step at the limit may be shrunk by a few wire units.

Rotations are done by scipy, the rounding here.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from humanpt.robot_gateway.links.alter import Correction

MM_PER_UNIT = 0.01  # PROTOCOL.md: dx, dy, dz in 0.01 mm
DEG_PER_UNIT = 0.01  # PROTOCOL.md: drx, dry, drz in 0.01 deg
# At the limit the rounded step may come out shorter than the exact clamped step: by the
# gateway's documented margin (up to 4 wire units) plus the rounding of each component.
SHRINK_TOLERANCE = 4 * 0.01 + 0.005 * np.sqrt(3)


def step_limits(max_speed_mm_s: float, max_angular_speed_deg_s: float, cycle_period_ms: float):
    """(mm, deg) per cycle from the configured speeds and cycle time."""
    cycle_s = cycle_period_ms / 1000.0
    return max_speed_mm_s * cycle_s, max_angular_speed_deg_s * cycle_s


# The default limits (AlterConfig: 100 mm/s, 60 deg/s, 28 ms cycle) per cycle.
LIMIT_MM, LIMIT_DEG = step_limits(100.0, 60.0, 28.0)


def wire_translation_mm(c: Correction) -> np.ndarray:
    """(3,) mm from the wire integers."""
    return np.array(c.deltas[:3], dtype=float) * MM_PER_UNIT


def wire_euler_deg(c: Correction) -> np.ndarray:
    """(drx, dry, drz) deg from the wire integers."""
    return np.array(c.deltas[3:], dtype=float) * DEG_PER_UNIT


def wire_rotation(c: Correction) -> Rotation:
    """dR = Rz(drz) Ry(dry) Rx(drx) of the wire values (intrinsic Z-Y-X in scipy)."""
    drx, dry, drz = wire_euler_deg(c)
    return Rotation.from_euler("ZYX", [drz, dry, drx], degrees=True)


def wire_angle_deg(c: Correction) -> float:
    return float(np.degrees(wire_rotation(c).magnitude()))


def euler_deg_of_rotvec(rv_rad) -> np.ndarray:
    """(drx, dry, drz) deg of a rotation vector, as the wire expresses it."""
    drz, dry, drx = Rotation.from_rotvec(np.asarray(rv_rad, dtype=float)).as_euler("ZYX", degrees=True)
    return np.array([drx, dry, drz])


def clamped(v, limit: float) -> np.ndarray:
    """(3,) ``v`` scaled down to norm ``limit`` if longer."""
    v = np.asarray(v, dtype=float)
    n = float(np.sqrt(np.sum(v * v)))
    return v if n <= limit else v * (limit / n)


def assert_wire_correction(c: Correction, dp_mm, rv_rad, limit_mm: float, limit_deg: float) -> None:
    """``c`` is the correction for the step ``dp_mm`` (3,) mm, ``rv_rad`` (3,) rotation
    vector (both already in the controller's ALTER frame): clamped to the limits by norm /
    angle with the direction kept, each value rounded to the nearest wire unit - or, where
    that rounding would exceed a limit, shrunk along the same direction to within it."""
    t = wire_translation_mm(c)
    assert np.linalg.norm(t) <= limit_mm + 1e-9, (t, limit_mm)
    assert wire_angle_deg(c) <= limit_deg + 1e-9, (wire_euler_deg(c), limit_deg)
    # Translation.
    dp_c = clamped(dp_mm, limit_mm)
    nearest = np.round(dp_c / MM_PER_UNIT) * MM_PER_UNIT
    if np.linalg.norm(nearest) <= limit_mm + 1e-9:  # rounding alone keeps it within
        assert np.all(np.abs(t - dp_c) <= MM_PER_UNIT / 2 + 1e-9), (t, dp_c)
    else:
        assert np.linalg.norm(t - dp_c) <= SHRINK_TOLERANCE, (t, dp_c)
    # Rotation, compared as the wire's Euler angles.
    rv_c = clamped(rv_rad, np.radians(limit_deg))
    r_exact = euler_deg_of_rotvec(rv_c)
    r = wire_euler_deg(c)
    r_nearest = np.round(r_exact / DEG_PER_UNIT) * DEG_PER_UNIT
    drx, dry, drz = r_nearest
    nearest_angle = np.degrees(Rotation.from_euler("ZYX", [drz, dry, drx], degrees=True).magnitude())
    if nearest_angle <= limit_deg + 1e-9:
        assert np.all(np.abs(r - r_exact) <= DEG_PER_UNIT / 2 + 1e-9), (r, r_exact)
    else:
        assert np.linalg.norm(r - r_exact) <= SHRINK_TOLERANCE, (r, r_exact)
