"""Single rotations on the filter's hot paths without scipy's per-call overhead.

scipy's ``from_matrix`` spends most of its time checking the matrix (determinant, a
Gramian compared with ``np.isclose``) before converting it. Here a rotation that clearly
passes those checks goes straight to the conversion, and a rotation vector becomes a matrix
by scipy's own arithmetic on plain floats, so each function returns exactly the numbers of
the library call named in its docstring (tested bit for bit); anything else goes through
that library call, so errors and odd input behave as before.
"""

from __future__ import annotations

import math

import numpy as np

from humanpt.schemas.convert import matrix_from_rotvec, rotvec_from_matrix, slerp_matrix

try:  # scipy's compiled Rotation backend, as humanpt.schemas.convert uses it
    from scipy.spatial.transform import _rotation_cy as _rot

    _FAST = all(
        hasattr(_rot, f)
        for f in (
            "_from_matrix_orthogonal",
            "as_rotvec",
            "as_matrix",
            "from_rotvec",
            "from_quat",
            "compose_quat",
            "inv",
        )
    )
except ImportError:  # pragma: no cover - another scipy
    _rot, _FAST = None, False

__all__ = ["matrix_of", "quat_of", "rotvec_of", "slerp"]


def matrix_of(rotvec: np.ndarray) -> np.ndarray:
    """``humanpt.schemas.convert.matrix_from_rotvec(rotvec)`` (scipy's ``from_rotvec`` and
    ``as_matrix``, their operations in the same order), the same numbers."""
    x, y, z = rotvec.tolist()
    angle = math.sqrt(x * x + y * y + z * z)
    if not (_FAST and angle < 1e300):  # another scipy, or not finite: scipy's numbers
        return matrix_from_rotvec(rotvec)
    if angle <= 1e-3:  # small angle Taylor series expansion
        angle2 = angle * angle
        scale = 0.5 - angle2 / 48 + angle2 * angle2 / 3840
    else:
        scale = math.sin(angle / 2) / angle
    x, y, z, w = scale * x, scale * y, scale * z, math.cos(angle / 2)
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    return np.array(
        [
            [x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw)],
            [2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw)],
            [2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2],
        ]
    )


def _clearly_rotation(R: list, off_tol: float, diag_tol: float) -> bool:
    """R (3x3 nested list) has ``R R^T`` within ``off_tol`` of 0 off the diagonal and
    ``diag_tol`` of 1 on it, and a determinant near 1."""
    (a, b, c), (d, e, f), (g, h, i) = R
    off = max(abs(a * d + b * e + c * f), abs(a * g + b * h + c * i), abs(d * g + e * h + f * i))
    diag = max(
        abs(a * a + b * b + c * c - 1.0),
        abs(d * d + e * e + f * f - 1.0),
        abs(g * g + h * h + i * i - 1.0),
    )
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return off < off_tol and diag < diag_tol and det > 0.5


def quat_of(R: np.ndarray) -> np.ndarray | bool:
    """scipy's ``from_matrix`` quaternion of a (3, 3) rotation that clearly passes its
    checks (det > 0; ``R R^T`` within 1e-12 of I off the diagonal and 1e-5 on it, where it
    would orthogonalise by SVD first); False for any other matrix (the callers then use the
    library call)."""
    if not _FAST or R.shape != (3, 3):
        return False
    if not _clearly_rotation(R.tolist(), 0.5e-12, 0.5e-5):
        return False
    return _rot._from_matrix_orthogonal(np.asarray(R, dtype=np.float64))


def rotvec_of(R: np.ndarray) -> np.ndarray:
    """``humanpt.schemas.convert.rotvec_from_matrix(R)``, the same numbers."""
    q = quat_of(R)
    if q is False:
        return rotvec_from_matrix(R)
    return _rot.as_rotvec(q[None])[0]


def slerp(R0: np.ndarray, R1: np.ndarray, s: float, q0=None, q1=None) -> np.ndarray:
    """``Slerp([0, 1], Rotation.from_matrix([R0, R1]))(s).as_matrix()`` for 0 <= s <= 1,
    the same numbers (``humanpt.schemas.convert.slerp_matrix`` computes that expression).
    ``q0``, ``q1``: :func:`quat_of` R0 and R1 when already known."""
    q0 = quat_of(R0) if q0 is None else q0
    q1 = quat_of(R1) if q1 is None else q1
    if q0 is False or q1 is False:
        return slerp_matrix(R0, R1, s)
    q0 = q0[None]
    rel = _rot.from_quat(_rot.compose_quat(_rot.inv(q0), q1[None]), normalize=True, copy=False)
    step = _rot.from_rotvec(np.asarray(s * _rot.as_rotvec(rel)[0], dtype=np.float64))[None]
    q = _rot.from_quat(_rot.compose_quat(q0, step), normalize=True, copy=False)
    return _rot.as_matrix(q)[0]
