"""Homogeneous transforms, the paper's chains and its six-vector X (Section 4, steps 8-10).

Conventions (DESIGN.md):

* A transform is a 4x4 numpy array named ``a_T_b``: the pose of frame ``b`` in frame ``a``,
  so ``a_p = a_T_b @ b_p`` and chains read like the paper,
  ``world_T_tob = world_T_flange @ flange_T_camera @ camera_T_tob``.
* Translations inside this library are in **millimetres** (the paper's unit). Messages use
  metres and quaternions; :mod:`humanpt.schemas.convert` converts at that boundary.
* Yaw, pitch, roll (psi, theta, phi) are Z-Y-X: ``R = Rz(psi) @ Ry(theta) @ Rx(phi)``,
  computed only through :class:`scipy.spatial.transform.Rotation` (``"ZYX"``, intrinsic).
* Rotation vectors (theta-u: axis times angle, rad), rotation angles and geodesics
  (:func:`slerp`) are scipy's too (the rotation vector -> matrix direction is OpenCV's
  Rodrigues, for speed): this module is the project's one implementation of each.
* The six-vector is ``X = (x, y, z, psi, theta, phi)`` in mm and degrees.

Every function accepts stacks: leading dimensions broadcast (``(..., 4, 4)``).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from .errors import GeometryError

try:  # the full install's OpenCV; the server's lean install has none (requirements/server.txt)
    from cv2 import Rodrigues as _cv2_rodrigues
except ImportError:
    _cv2_rodrigues = None

__all__ = [
    "make_transform",
    "invert_transform",
    "compose",
    "chain_world_T_tob",
    "transform_points",
    "check_rigid",
    "rotation_from_ypr_deg",
    "ypr_deg_from_rotation",
    "x_from_transform",
    "transform_from_x",
    "matrix_from_rotvec",
    "rotvec_from_matrix",
    "rotation_angle_rad",
    "slerp",
    "interpolate_transform",
    "apply_step",
]

EULER_SEQUENCE = "ZYX"  # intrinsic: R = Rz(psi) Ry(theta) Rx(phi)


def make_transform(rotation: np.ndarray, translation_mm: np.ndarray) -> np.ndarray:
    """Eq. (8)/(9) form ``[[R, t], [0, 1]]`` from a rotation (..., 3, 3) and a translation
    (..., 3) in mm. Returns (..., 4, 4)."""
    rotation = np.asarray(rotation, dtype=float)
    translation_mm = np.asarray(translation_mm, dtype=float)
    if rotation.shape[-2:] != (3, 3) or translation_mm.shape[-1:] != (3,):
        raise ValueError(
            f"make_transform needs rotation (..., 3, 3) and translation (..., 3), got "
            f"{rotation.shape} and {translation_mm.shape}"
        )
    batch = np.broadcast_shapes(rotation.shape[:-2], translation_mm.shape[:-1])
    out = np.zeros(batch + (4, 4))
    out[..., :3, :3] = rotation
    out[..., :3, 3] = translation_mm
    out[..., 3, 3] = 1.0
    return out


def _as_transform(a_T_b: np.ndarray, name: str = "transform") -> np.ndarray:
    a_T_b = np.asarray(a_T_b, dtype=float)
    if a_T_b.shape[-2:] != (4, 4):
        raise ValueError(f"{name} must have shape (..., 4, 4), got {a_T_b.shape}")
    return a_T_b


def invert_transform(a_T_b: np.ndarray) -> np.ndarray:
    """Return ``b_T_a`` for a rigid ``a_T_b`` (..., 4, 4), using ``R^T`` (no general
    matrix inverse)."""
    a_T_b = _as_transform(a_T_b)
    rotation_t = np.swapaxes(a_T_b[..., :3, :3], -1, -2)
    translation = -np.einsum("...ij,...j->...i", rotation_t, a_T_b[..., :3, 3])
    return make_transform(rotation_t, translation)


def compose(*transforms: np.ndarray) -> np.ndarray:
    """Product of a chain, left to right: ``compose(a_T_b, b_T_c) == a_T_b @ b_T_c``.
    Stacks broadcast."""
    if not transforms:
        raise ValueError("compose needs at least one transform")
    out = _as_transform(transforms[0])
    for t in transforms[1:]:
        out = out @ _as_transform(t)
    return out


def chain_world_T_tob(
    world_T_flange: np.ndarray, flange_T_camera: np.ndarray, camera_T_tob: np.ndarray
) -> np.ndarray:
    """Section 4, step 8: ``world_T_tob = world_T_flange @ flange_T_camera @ camera_T_tob``
    (the paper's ``W T_G = W T_F . F T_C . C T_G``). All (..., 4, 4), translations in mm."""
    return compose(world_T_flange, flange_T_camera, camera_T_tob)


def transform_points(a_T_b: np.ndarray, b_p_mm: np.ndarray) -> np.ndarray:
    """Map points (..., 3) given in frame ``b`` into frame ``a``: ``a_p = R b_p + t``."""
    a_T_b = _as_transform(a_T_b)
    b_p_mm = np.asarray(b_p_mm, dtype=float)
    return np.einsum("...ij,...j->...i", a_T_b[..., :3, :3], b_p_mm) + a_T_b[..., :3, 3]


def check_rigid(a_T_b: np.ndarray, tol: float = 1e-6, name: str = "transform") -> None:
    """Raise :class:`GeometryError` unless ``a_T_b`` is a proper rigid transform: finite,
    orthonormal rotation with determinant +1 (within ``tol``), last row ``[0, 0, 0, 1]``."""
    a_T_b = _as_transform(a_T_b, name)
    if not np.all(np.isfinite(a_T_b)):
        raise GeometryError(f"{name} contains non-finite values")
    rot = a_T_b[..., :3, :3]
    ortho = np.max(np.abs(np.swapaxes(rot, -1, -2) @ rot - np.eye(3)))
    if ortho > tol:
        raise GeometryError(f"{name}: rotation is not orthonormal (max |R^T R - I| = {ortho:.3g})")
    det = np.linalg.det(rot)
    if np.any(np.abs(det - 1.0) > tol):
        raise GeometryError(f"{name}: rotation is a reflection or scaled (det = {np.min(det):.6g})")
    bottom = np.max(np.abs(a_T_b[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])))
    if bottom > tol:
        raise GeometryError(f"{name}: last row is not [0, 0, 0, 1]")


def rotation_from_ypr_deg(ypr_deg: np.ndarray) -> np.ndarray:
    """Yaw, pitch, roll (..., 3) = (psi, theta, phi) in degrees -> rotation (..., 3, 3),
    ``R = Rz(psi) Ry(theta) Rx(phi)`` (scipy ``from_euler("ZYX", ...)``)."""
    ypr_deg = np.asarray(ypr_deg, dtype=float)
    if ypr_deg.shape[-1:] != (3,):
        raise ValueError(f"ypr_deg must have shape (..., 3), got {ypr_deg.shape}")
    flat = ypr_deg.reshape(-1, 3)
    mats = Rotation.from_euler(EULER_SEQUENCE, flat, degrees=True).as_matrix()
    return mats.reshape(ypr_deg.shape[:-1] + (3, 3))


def ypr_deg_from_rotation(rotation: np.ndarray, assume_valid: bool = False) -> np.ndarray:
    """Rotation (..., 3, 3) -> yaw, pitch, roll (..., 3) in degrees, Z-Y-X (inverse of
    :func:`rotation_from_ypr_deg`). psi, phi in (-180, 180], theta in [-90, 90]; at
    theta = +-90 deg (gimbal lock) scipy picks one of the equivalent triples.
    ``assume_valid`` as in :func:`rotvec_from_matrix`."""
    rotation = np.asarray(rotation, dtype=float)
    if rotation.shape[-2:] != (3, 3):
        raise ValueError(f"rotation must have shape (..., 3, 3), got {rotation.shape}")
    flat = rotation.reshape(-1, 3, 3)
    ypr = Rotation.from_matrix(flat, assume_valid=assume_valid).as_euler(EULER_SEQUENCE, degrees=True)
    return ypr.reshape(rotation.shape[:-2] + (3,))


def oat_deg_from_rotation(rotation: Rotation) -> np.ndarray:
    """VAL II's O, A, T of a rotation (Euler Z-Y-Z, deg).  At A = 0 (or 180) only O + T
    (O - T) is defined; scipy then sets T = 0 and warns: the rotation is still exact, so the
    warning is not passed on."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return rotation.as_euler("ZYZ", degrees=True)


def x_from_transform(a_T_b: np.ndarray) -> np.ndarray:
    """Section 4, steps 9-10: the six-vector ``X = (x, y, z, psi, theta, phi)`` (..., 6)
    of frame ``b`` in frame ``a``, in mm and degrees (Z-Y-X yaw, pitch, roll)."""
    a_T_b = _as_transform(a_T_b)
    return np.concatenate([a_T_b[..., :3, 3], ypr_deg_from_rotation(a_T_b[..., :3, :3])], axis=-1)


def transform_from_x(x_mm_deg: np.ndarray) -> np.ndarray:
    """Inverse of :func:`x_from_transform`: (..., 6) in mm and degrees -> (..., 4, 4)."""
    x_mm_deg = np.asarray(x_mm_deg, dtype=float)
    if x_mm_deg.shape[-1:] != (6,):
        raise ValueError(f"X must have shape (..., 6), got {x_mm_deg.shape}")
    return make_transform(rotation_from_ypr_deg(x_mm_deg[..., 3:]), x_mm_deg[..., :3])


def matrix_from_rotvec(rotvec_rad) -> np.ndarray:
    """Rotation vector(s) (..., 3) - axis times angle, rad - -> rotation matrices
    (..., 3, 3): Rodrigues' formula, ``Rotation.from_rotvec(rotvec_rad).as_matrix()`` to
    rounding. OpenCV's ``cv2.Rodrigues`` computes it: a tenth of scipy's per-call cost, and
    the filter, the controller and the twin turn one small step at a time. (Its inverse is
    not used: near zero angle it loses digits; :func:`rotvec_from_matrix` is scipy's.)
    Without OpenCV (the server's install: only the gateway calls this there) scipy does."""
    v = np.asarray(rotvec_rad, dtype=float)
    if v.shape[-1:] != (3,):
        raise ValueError(f"rotation vectors must have shape (..., 3), got {v.shape}")
    if _cv2_rodrigues is None:
        return Rotation.from_rotvec(v.reshape(-1, 3)).as_matrix().reshape(v.shape[:-1] + (3, 3))
    if v.shape == (3,):
        return _cv2_rodrigues(v)[0]
    flat = [_cv2_rodrigues(r)[0] for r in v.reshape(-1, 3)]
    return np.array(flat).reshape(v.shape[:-1] + (3, 3))


def rotvec_from_matrix(rotation: np.ndarray, assume_valid: bool = False) -> np.ndarray:
    """Rotation matrix (3, 3) or (n, 3, 3) -> rotation vector (3,) or (n, 3), rad, angle in
    [0, pi]: ``Rotation.from_matrix(rotation, assume_valid=...).as_rotvec()``.

    ``assume_valid``: skip scipy's orthonormality check (and its repair of a matrix that
    fails it); for products of rotations, where the check costs more than the conversion
    and would pass anyway."""
    return Rotation.from_matrix(rotation, assume_valid=assume_valid).as_rotvec()


def rotation_angle_rad(rotation: np.ndarray, assume_valid: bool = False) -> np.ndarray:
    """Angle (rad, in [0, pi]) of rotation matrices (..., 3, 3), ``Rotation.magnitude()``;
    ``assume_valid`` as in :func:`rotvec_from_matrix`. A float for one matrix."""
    return Rotation.from_matrix(rotation, assume_valid=assume_valid).magnitude()


def slerp(r0: np.ndarray, r1: np.ndarray, s, assume_valid: bool = False) -> np.ndarray:
    """The rotation a fraction ``s`` of the way along the shortest geodesic from ``r0`` to
    ``r1`` (3, 3) (both in the same frame): ``r0 exp(s log(r0^T r1))``. Any real ``s``:
    0 gives r0, 1 gives r1, beyond [0, 1] it extrapolates at the same angular rate.
    Equal to ``Slerp([0, 1], Rotation.from_matrix([r0, r1]))(s)`` for s in [0, 1];
    ``assume_valid`` (r0 and r1 are rotations) as in :func:`rotvec_from_matrix`."""
    r0 = np.asarray(r0, dtype=float)
    step = rotvec_from_matrix(r0.T @ r1, assume_valid=assume_valid)
    return r0 @ matrix_from_rotvec(s * step)


def interpolate_transform(a_T_b0: np.ndarray, a_T_b1: np.ndarray, s, assume_valid: bool = False) -> np.ndarray:
    """The pose (4, 4) a fraction ``s`` of the way from ``a_T_b0`` to ``a_T_b1``: the
    translation on the straight line, the rotation on the geodesic (:func:`slerp`). Any
    real ``s``: beyond [0, 1] it extrapolates at the same linear and angular rates.
    ``assume_valid`` as in :func:`slerp`."""
    t0 = np.asarray(a_T_b0, dtype=float)
    t1 = np.asarray(a_T_b1, dtype=float)
    out = np.eye(4)
    out[:3, :3] = slerp(t0[:3, :3], t1[:3, :3], s, assume_valid=assume_valid)
    out[:3, 3] = t0[:3, 3] + s * (t1[:3, 3] - t0[:3, 3])
    return out


def apply_step(a_T_b: np.ndarray, d_translation: np.ndarray, d_rotvec_rad: np.ndarray) -> np.ndarray:
    """``a_T_b`` (4, 4) after a step given in frame ``a`` about b's origin: rotated by
    ``exp(d_rotvec_rad)`` (3,) and moved by ``d_translation`` (3,) (the unit of a_T_b's
    translation): ``R' = exp(d_r) R``, ``t' = t + d_t``."""
    out = np.array(a_T_b, dtype=float)
    out[:3, :3] = matrix_from_rotvec(d_rotvec_rad) @ out[:3, :3]
    out[:3, 3] += d_translation
    return out
