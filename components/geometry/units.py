"""Units at the edges, in one place (issue 30.5).

Cores work in SI (m, rad, s); people, files, configs, robot links and the paper's maths work
in mm and deg. A pose crosses that edge as a 4x4 homogeneous transform (or a stack of them,
(..., 4, 4)) whose translation changes unit and whose rotation does not. These are the only
conversions of a transform between m and mm: a module that needs one imports it from here.

Each returns a new float array (the input is never changed) and scales by exactly ``1e3`` or
``1e-3`` (the same floating-point operation the inline ``T[:3, 3] *= 1e3`` of earlier builds
did: recordings replay bit for bit).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MM_PER_M", "M_PER_MM", "to_m", "to_mm"]

MM_PER_M = 1e3
M_PER_MM = 1e-3


def to_mm(T_m) -> np.ndarray:
    """A transform (4, 4) or a stack (..., 4, 4) with its translation in m -> in mm."""
    T = np.array(T_m, dtype=float)
    T[..., :3, 3] *= MM_PER_M
    return T


def to_m(T_mm) -> np.ndarray:
    """A transform (4, 4) or a stack (..., 4, 4) with its translation in mm -> in m."""
    T = np.array(T_mm, dtype=float)
    T[..., :3, 3] *= M_PER_MM
    return T
