"""Z-Y-X Euler angles (the wire's convention) <-> rotations, exactly as scipy computes them.

The ALTER codec converts poses and corrections every 28 ms cycle at both ends of the link;
through the public ``scipy.spatial.transform.Rotation`` API each conversion costs 10-30 us
of array-API wrapping and checks, more than the arithmetic. These functions call scipy's
compiled Rotation backend directly: the public API calls the very same functions, so the
numbers are the same (tests/alter compare them bit for bit). On a scipy without that
backend they fall back to the public API.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

try:  # scipy's compiled backend of Rotation (1.17)
    from scipy.spatial.transform import _rotation_cy as _rot

    _FAST = all(
        hasattr(_rot, f)
        for f in (
            "from_euler",
            "as_euler",
            "_from_matrix_orthogonal",
            "as_matrix",
            "from_rotvec",
            "magnitude",
        )
    )
except ImportError:  # another scipy: the public API below
    _rot, _FAST = None, False

# A matrix this close to orthonormal (rows, in plain float arithmetic) passes scipy's own
# check (Gramian within 1e-12 of I) too, so scipy would not re-orthogonalise it.
_ORTHONORMAL_TOL = 1e-13


def _is_rotation(R: np.ndarray) -> bool:
    """Orthonormal rows within _ORTHONORMAL_TOL and det > 0: a proper rotation."""
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    tol = _ORTHONORMAL_TOL
    return (
        abs(a * a + b * b + c * c - 1.0) <= tol
        and abs(d * d + e * e + f * f - 1.0) <= tol
        and abs(g * g + h * h + i * i - 1.0) <= tol
        and abs(a * d + b * e + c * f) <= tol
        and abs(a * g + b * h + c * i) <= tol
        and abs(d * g + e * h + f * i) <= tol
        and a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) > 0.5
    )


if _FAST:

    def matrix_from_euler_zyx_deg(angles_deg) -> np.ndarray:
        """``Rotation.from_euler("ZYX", angles_deg, degrees=True).as_matrix()``."""
        quat = _rot.from_euler("ZYX", np.asarray(angles_deg, dtype=np.float64), True)
        return _rot.as_matrix(quat[None])[0]

    def euler_zyx_deg_from_matrix(R: np.ndarray) -> np.ndarray:
        """``Rotation.from_matrix(R).as_euler("ZYX", degrees=True)`` for one (3, 3) matrix."""
        R = np.array(R, dtype=np.float64)
        if R.shape != (3, 3) or not _is_rotation(R):  # scipy's checks and repairs
            return Rotation.from_matrix(R).as_euler("ZYX", degrees=True)
        return np.asarray(_rot.as_euler(_rot._from_matrix_orthogonal(R)[None], "ZYX", True)[0])

    def euler_zyx_deg_from_rotvec(rotvec_rad) -> np.ndarray:
        """``Rotation.from_rotvec(rotvec_rad).as_euler("ZYX", degrees=True)``."""
        quat = _rot.from_rotvec(np.asarray(rotvec_rad, dtype=np.float64))
        return np.asarray(_rot.as_euler(quat[None], "ZYX", True)[0])

    def angle_from_euler_zyx_deg(angles_deg) -> float:
        """``Rotation.from_euler("ZYX", angles_deg, degrees=True).magnitude()`` (rad)."""
        quat = _rot.from_euler("ZYX", np.asarray(angles_deg, dtype=np.float64), True)
        return float(_rot.magnitude(quat[None])[0])

else:  # pragma: no cover - only on a scipy without the backend

    def matrix_from_euler_zyx_deg(angles_deg) -> np.ndarray:
        return Rotation.from_euler("ZYX", angles_deg, degrees=True).as_matrix()

    def euler_zyx_deg_from_matrix(R: np.ndarray) -> np.ndarray:
        return Rotation.from_matrix(R).as_euler("ZYX", degrees=True)

    def euler_zyx_deg_from_rotvec(rotvec_rad) -> np.ndarray:
        return Rotation.from_rotvec(rotvec_rad).as_euler("ZYX", degrees=True)

    def angle_from_euler_zyx_deg(angles_deg) -> float:
        return float(Rotation.from_euler("ZYX", angles_deg, degrees=True).magnitude())
