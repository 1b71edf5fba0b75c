"""The pseudo stereo vision system (PSVS): eq. (1)-(6) of Pachidis et al., Section 2.

Frames and units
----------------
* The **camera frame** has its origin at the optical centre O of the *real* camera, z along
  its optical axis (into the scene), x along the image u axis, y along the image v axis.
  All 3D coordinates are in **millimetres**; image coordinates are in **pixels** of the
  complex image.
* The PSVS makes two *virtual* cameras, parallel to the real one (same axes; see R_k below), with optical
  centres given by eq. (3): right (virtual camera 1) ``O1 = (b/2, 0, -b/2)``, left
  (virtual camera 2) ``O2 = (-b/2 - m, 0, -b/2 + l)``; m and l come from refraction in the
  beam-splitter plate, eq. (5), (6).
* Each virtual camera is a pinhole with the intrinsic matrix of eq. (1)::

      u = u0_k + a_u X/Z + c Y/Z,   v = v0_k + a_v Y/Z,   (X, Y, Z) = R_k^T (P - O_k)

  which is exactly the inverse of eq. (2) (and, with eq. (3), of eq. (4)); the paper's
  equations carry no skew term, so the triangulators first remove the skew
  (``u - c (v - v0)/a_v``), which is a no-op for c = 0.
* ``R_k = camera_R_virtual`` is the rotation of virtual camera k's axes in the camera frame:
  identity in the paper's model (the mirrors perfectly aligned). A mirror tilted by alpha
  about an axis in its plane rotates the virtual camera by 2 alpha about that axis
  (:func:`virtual_rotation_from_mirror_tilt_deg`); the PSVS model takes the virtual
  camera's rotation. Triangulation maps each view's ideal pixels through the rotation
  homography ``A_k R_k A_k^-1`` into the parallel camera with the same centre and
  intrinsics (:func:`parallel_pixels`), then applies the unchanged eq. (4)/(2); with
  R_k = I nothing is mapped.
* Lens distortion belongs to the one real lens: ideal complex-image pixels are distorted
  around the real camera's intrinsics (``u0, v0``) with OpenCV's model
  (:mod:`humanpt.geometry.distortion`). Triangulators take *ideal* (undistorted) pixels;
  :func:`project` and :func:`triangulate` do the whole chain.

Every function accepts stacks of points: leading dimensions broadcast.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .distortion import as_dist_coeffs, distort_pixels, undistort_pixels
from .errors import GeometryError
from .transforms import matrix_from_rotvec

__all__ = [
    "refraction_angle_deg",
    "psvs_m_l_mm",
    "virtual_camera_centres_mm",
    "intrinsic_matrix",
    "virtual_rotation_from_mirror_tilt_deg",
    "PinholeCamera",
    "PsvsParams",
    "project_pinhole",
    "projection_jacobian",
    "project",
    "in_image",
    "parallel_pixels",
    "eq4_points_mm",
    "triangulate_eq4",
    "triangulate_eq2",
    "triangulate_lsq",
    "triangulate",
    "TRIANGULATION_METHODS",
]

TRIANGULATION_METHODS = ("eq4", "eq2", "lsq")


# --------------------------------------------------------------------------- eq. (5), (6)


def refraction_angle_deg(omega1_deg: float, n_glass: float = 1.5, n_air: float = 1.0) -> float:
    """Refraction angle theta_r (deg) in the beam-splitter plate (Snell's law).

    ``omega1`` is the angle between the optical axis and the mirror plane, so the incidence
    angle is ``theta_i = 90 deg - omega1`` (Section 2, symbol x) and
    ``n_air sin(theta_i) = n_glass sin(theta_r)``.
    """
    if not (0.0 < omega1_deg <= 90.0):
        raise ValueError(f"omega1 must be in (0, 90] degrees, got {omega1_deg}")
    if not (n_glass > 0 and n_air > 0):
        raise ValueError(f"refraction indices must be positive, got {n_glass}, {n_air}")
    sin_r = n_air * math.sin(math.radians(90.0 - omega1_deg)) / n_glass
    if sin_r > 1.0:
        raise ValueError(
            f"no refracted ray: total internal reflection for omega1={omega1_deg}, "
            f"n_air={n_air}, n_glass={n_glass}"
        )
    return math.degrees(math.asin(sin_r))


def psvs_m_l_mm(
    thickness_mm: float = 1.0,
    omega1_deg: float = 45.0,
    n_glass: float = 1.5,
    n_air: float = 1.0,
) -> tuple[float, float]:
    """Eq. (5) and (6): the PSVS refraction parameters (m, l) in mm.

    ``m = d cos(omega1 + theta_r) / cos(theta_r)`` (shift of the left virtual optical axis
    along x) and ``l = d / cos(theta_r) (1 - sin(omega1 + theta_r) + cos(omega1 + theta_r)
    tan(omega1))`` (shift of O2 along the optical axis), with d the beam splitter's thickness
    in mm. d = 1 mm, omega1 = 45 deg, n = 1.5 gives m = 0.329 mm, l = 0.378 mm (paper).
    """
    if not (thickness_mm >= 0 and math.isfinite(thickness_mm)):
        raise ValueError(f"mirror thickness must be finite and >= 0 mm, got {thickness_mm}")
    if omega1_deg >= 90.0:
        raise ValueError("omega1 must be below 90 deg (tan(omega1) in eq. (6))")
    theta_r = math.radians(refraction_angle_deg(omega1_deg, n_glass, n_air))
    omega1 = math.radians(omega1_deg)
    m = thickness_mm * math.cos(omega1 + theta_r) / math.cos(theta_r)
    l = (
        thickness_mm
        / math.cos(theta_r)
        * (1.0 - math.sin(omega1 + theta_r) + math.cos(omega1 + theta_r) * math.tan(omega1))
    )
    return m, l


def virtual_camera_centres_mm(
    baseline_mm: float, m_mm: float, l_mm: float
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (3): optical centres (x0, y0, z0) in mm of the right (O1) and left (O2) virtual
    cameras in the camera frame: ``O1 = (b/2, 0, -b/2)``, ``O2 = (-b/2 - m, 0, -b/2 + l)``."""
    b = float(baseline_mm)
    return (
        np.array([b / 2.0, 0.0, -b / 2.0]),
        np.array([-b / 2.0 - m_mm, 0.0, -b / 2.0 + l_mm]),
    )


def intrinsic_matrix(a_u: float, a_v: float, u0: float, v0: float, skew: float = 0.0) -> np.ndarray:
    """Eq. (1): ``A = [[a_u, c, u0], [0, a_v, v0], [0, 0, 1]]`` (pixels). The paper prints
    the last row as zeros, a misprint: a projective intrinsic matrix ends in ``[0, 0, 1]``."""
    return np.array([[a_u, skew, u0], [0.0, a_v, v0], [0.0, 0.0, 1.0]], dtype=float)


def virtual_rotation_from_mirror_tilt_deg(tilt_deg: float, axis=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Rotation vector (3,), deg, of a virtual camera whose mirror is tilted by
    ``tilt_deg`` about ``axis`` (3,), a direction in the mirror's plane, given in the
    virtual camera's frame (i.e. the tilt axis seen through the mirrors after it).

    Reflection in a mirror rotated by alpha about an axis a in its plane is
    ``R_a(alpha) M R_a(-alpha) = R_a(2 alpha) M`` (M a = a): the virtual camera turns by
    twice the tilt, ``2 alpha a``. Use the result as ``rotvec_right_deg`` /
    ``rotvec_left_deg``. (The tilt also moves the virtual optical centre by about
    2 alpha times the distance from the axis - 0.1 mm for 0.05 deg at 50 mm - which this
    does not model: give it through the baseline, m or l.)"""
    a = np.asarray(axis, dtype=float).reshape(3)
    norm = np.linalg.norm(a)
    if not (np.isfinite(norm) and norm > 0):
        raise ValueError(f"axis must be a non-zero finite 3-vector, got {axis!r}")
    return 2.0 * _finite("tilt_deg", tilt_deg) * a / norm


# --------------------------------------------------------------------------- cameras


def _finite(name: str, value: float) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    return value


_IDENTITY_3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


@dataclass(frozen=True)
class PinholeCamera:
    """One camera of a stereo pair (eq. (2)): axes parallel to the camera frame unless
    rotated.

    ``a_u, a_v`` scale factors (px), ``u0, v0`` image centre (px), ``skew`` the eq. (1)
    parameter c (px), ``centre_mm`` the optical centre (x0, y0, z0) in the camera frame (mm),
    ``camera_R_virtual`` (3x3, rows) the rotation of this camera's axes in the camera frame
    (identity: the parallel camera of the paper): a point P (camera frame) is at
    ``R^T (P - O)`` in this camera's frame. Orthonormal with det +1 to 1e-9.
    """

    a_u: float
    a_v: float
    u0: float
    v0: float
    centre_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    skew: float = 0.0
    camera_R_virtual: tuple[tuple[float, float, float], ...] = _IDENTITY_3

    def __post_init__(self) -> None:
        for name in ("a_u", "a_v"):
            value = _finite(name, getattr(self, name))
            if value <= 0:
                raise ValueError(f"PinholeCamera.{name} must be > 0 px, got {value}")
            object.__setattr__(self, name, value)
        for name in ("u0", "v0", "skew"):
            object.__setattr__(self, name, _finite(name, getattr(self, name)))
        centre = tuple(_finite("centre_mm", c) for c in np.asarray(self.centre_mm).ravel())
        if len(centre) != 3:
            raise ValueError(f"centre_mm must have 3 values, got {len(centre)}")
        object.__setattr__(self, "centre_mm", centre)
        rot = np.asarray(self.camera_R_virtual, dtype=float)
        if rot.shape != (3, 3) or not np.all(np.isfinite(rot)):
            raise ValueError(f"camera_R_virtual must be a finite 3x3 matrix, got {rot.tolist()}")
        if not (
            np.allclose(rot @ rot.T, np.eye(3), rtol=0, atol=1e-9)
            and abs(np.linalg.det(rot) - 1.0) < 1e-9
        ):
            raise ValueError(
                f"camera_R_virtual must be a rotation (orthonormal, det +1), got {rot.tolist()}"
            )
        object.__setattr__(self, "camera_R_virtual", tuple(tuple(float(x) for x in r) for r in rot))

    @property
    def matrix(self) -> np.ndarray:
        """Eq. (1) intrinsic matrix (3, 3)."""
        return intrinsic_matrix(self.a_u, self.a_v, self.u0, self.v0, self.skew)

    @property
    def centre(self) -> np.ndarray:
        """Optical centre (3,) in mm, camera frame."""
        return np.array(self.centre_mm)

    @property
    def rotation(self) -> np.ndarray:
        """``camera_R_virtual`` (3, 3) as an array."""
        return np.array(self.camera_R_virtual)

    @property
    def is_parallel(self) -> bool:
        """True when the axes are the camera frame's (R = I exactly): the paper's model."""
        return self.camera_R_virtual == _IDENTITY_3


_DEFAULT_M_MM, _DEFAULT_L_MM = psvs_m_l_mm(1.0, 45.0, 1.5, 1.0)


@dataclass(frozen=True)
class PsvsParams:
    """Geometry of a PSVS (Section 2) - everything eq. (1)-(4) and the distortion need.

    Defaults: a 640 x 480 camera, a_u = a_v = 1000 px, no skew, (u0, v0) = (320, 240),
    baseline b = 90 mm, and m, l from a 1 mm, 45 deg, n = 1.5 beam splitter (eq. (5), (6)),
    no distortion. Eq. (3): both virtual cameras share a_u, a_v (and the skew); their image
    centres ``u0_right, v0_right, u0_left, v0_left`` (None: the real camera's u0, v0, which
    are also the centre of the lens distortion) are resolved in ``right_camera`` /
    ``left_camera``, so ``dataclasses.replace(params, u0=...)`` moves all of them.

    Fields: ``image_size_px`` (width, height); ``a_u, a_v, skew, u0, v0`` in px;
    ``baseline_mm``, ``m_mm``, ``l_mm`` in mm; ``dist_coeffs`` OpenCV (k1, k2, p1, p2, k3);
    ``rotvec_right_deg``, ``rotvec_left_deg`` (3,) the rotation vector (deg, camera frame)
    of each virtual camera's axes (``camera_R_virtual``; (0, 0, 0): parallel, as in the
    paper). A rotation about y pans a view: its image shifts by ``-a_u tan(angle)`` px
    along u; about x it tilts it (``+a_v tan(angle)`` along v); a mirror tilt of alpha is a
    rotation of 2 alpha (:func:`virtual_rotation_from_mirror_tilt_deg`).
    """

    image_size_px: tuple[int, int] = (640, 480)
    a_u: float = 1000.0
    a_v: float = 1000.0
    skew: float = 0.0
    u0: float = 320.0
    v0: float = 240.0
    baseline_mm: float = 90.0
    m_mm: float = _DEFAULT_M_MM
    l_mm: float = _DEFAULT_L_MM
    dist_coeffs: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    u0_right: float | None = None
    v0_right: float | None = None
    u0_left: float | None = None
    v0_left: float | None = None
    rotvec_right_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotvec_left_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    _cameras: tuple = field(default=(), init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        size = tuple(self.image_size_px)
        if len(size) != 2 or not all(
            isinstance(s, int | np.integer) and not isinstance(s, bool) and s > 0 for s in size
        ):
            raise ValueError(
                f"image_size_px must be two positive integers (width, height), got {size!r}"
            )
        object.__setattr__(self, "image_size_px", (int(size[0]), int(size[1])))
        for name in ("a_u", "a_v", "baseline_mm"):
            value = _finite(name, getattr(self, name))
            if value <= 0:
                raise ValueError(f"PsvsParams.{name} must be > 0, got {value}")
            object.__setattr__(self, name, value)
        for name in ("skew", "u0", "v0", "m_mm", "l_mm"):
            object.__setattr__(self, name, _finite(name, getattr(self, name)))
        for name in ("m_mm", "l_mm"):
            if abs(getattr(self, name)) >= self.baseline_mm / 2:
                raise ValueError(
                    f"PsvsParams.{name} = {getattr(self, name)} mm is not a refraction shift "
                    f"(must be well below b/2 = {self.baseline_mm / 2} mm)"
                )
        for name in ("u0_right", "v0_right", "u0_left", "v0_left"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _finite(name, value))
        object.__setattr__(
            self, "dist_coeffs", tuple(float(x) for x in as_dist_coeffs(self.dist_coeffs))
        )
        rotations = []
        for name in ("rotvec_right_deg", "rotvec_left_deg"):
            vec = tuple(_finite(name, x) for x in np.asarray(getattr(self, name)).ravel())
            if len(vec) != 3:
                raise ValueError(f"PsvsParams.{name} must have 3 values, got {len(vec)}")
            if math.hypot(*vec) > 30.0:
                raise ValueError(
                    f"PsvsParams.{name} = {vec} deg is not a small mirror misalignment "
                    "(at most 30 deg)"
                )
            object.__setattr__(self, name, vec)
            rotations.append(
                _IDENTITY_3 if not any(vec) else matrix_from_rotvec(np.radians(vec))
            )
        right_c, left_c = virtual_camera_centres_mm(self.baseline_mm, self.m_mm, self.l_mm)

        def pick(value, default):
            return default if value is None else value

        cams = (
            PinholeCamera(
                self.a_u,
                self.a_v,
                pick(self.u0_right, self.u0),
                pick(self.v0_right, self.v0),
                right_c,
                self.skew,
                rotations[0],
            ),
            PinholeCamera(
                self.a_u,
                self.a_v,
                pick(self.u0_left, self.u0),
                pick(self.v0_left, self.v0),
                left_c,
                self.skew,
                rotations[1],
            ),
        )
        object.__setattr__(self, "_cameras", cams)

    @classmethod
    def from_mirror(
        cls,
        thickness_mm: float = 1.0,
        omega1_deg: float = 45.0,
        n_glass: float = 1.5,
        n_air: float = 1.0,
        **kwargs,
    ) -> PsvsParams:
        """Build the parameters with m, l from the beam splitter by eq. (5), (6); other
        fields as keyword arguments."""
        if "m_mm" in kwargs or "l_mm" in kwargs:
            raise ValueError("from_mirror computes m_mm and l_mm; do not pass them")
        m, l = psvs_m_l_mm(thickness_mm, omega1_deg, n_glass, n_air)
        return cls(m_mm=m, l_mm=l, **kwargs)

    @property
    def right_camera(self) -> PinholeCamera:
        """Virtual camera 1 (right), optical centre O1 of eq. (3)."""
        return self._cameras[0]

    @property
    def left_camera(self) -> PinholeCamera:
        """Virtual camera 2 (left), optical centre O2 of eq. (3)."""
        return self._cameras[1]

    @property
    def real_camera_matrix(self) -> np.ndarray:
        """Eq. (1) for the real camera (centre of the lens distortion)."""
        return intrinsic_matrix(self.a_u, self.a_v, self.u0, self.v0, self.skew)

    @property
    def has_distortion(self) -> bool:
        return any(self.dist_coeffs)

    @property
    def is_parallel(self) -> bool:
        """Both virtual cameras parallel to the real one (no rotation): the paper's model."""
        return self._cameras[0].is_parallel and self._cameras[1].is_parallel


def in_image(params: PsvsParams, uv_px: np.ndarray, margin_px: float = 0.0) -> np.ndarray:
    """Boolean mask (...,): pixels (..., 2) inside the complex image, at least
    ``margin_px`` from its border (pixel centres at integers, the image spans
    [-0.5, size - 0.5])."""
    uv = np.asarray(uv_px, dtype=float)
    width, height = params.image_size_px
    lo = -0.5 + margin_px
    return (
        (uv[..., 0] >= lo)
        & (uv[..., 0] <= width - 0.5 - margin_px)
        & (uv[..., 1] >= lo)
        & (uv[..., 1] <= height - 0.5 - margin_px)
    )


# --------------------------------------------------------------------------- forward model


def _points(camera_p_mm) -> np.ndarray:
    p = np.asarray(camera_p_mm, dtype=float)
    if p.shape[-1:] != (3,):
        raise ValueError(f"points must have shape (..., 3), got {p.shape}")
    return p


def _pixels(uv_px, name: str) -> np.ndarray:
    uv = np.asarray(uv_px, dtype=float)
    if uv.shape[-1:] != (2,):
        raise ValueError(f"{name} must have shape (..., 2), got {uv.shape}")
    return uv


def _in_camera(camera: PinholeCamera, camera_p_mm) -> np.ndarray:
    """``R^T (P - O)`` (..., 3): points in the (virtual) camera's own frame, mm."""
    rel = _points(camera_p_mm) - camera.centre
    if camera.is_parallel:
        return rel
    return rel @ camera.rotation  # row vectors: (R^T r)^T = r^T R


def project_pinhole(camera: PinholeCamera, camera_p_mm: np.ndarray) -> np.ndarray:
    """Eq. (1)/(2) forward: points (..., 3) in the camera frame (mm) -> ideal pixels (..., 2)
    of one camera: ``u = u0 + a_u X/Z + c Y/Z``, ``v = v0 + a_v Y/Z`` with
    ``(X, Y, Z) = R^T (P - O)`` (R = ``camera_R_virtual``, identity for the paper's parallel
    cameras). Raises :class:`GeometryError` for points not in front (Z <= 0)."""
    rel = _in_camera(camera, camera_p_mm)
    depth = rel[..., 2]
    if np.any(~(depth > 0)):
        raise GeometryError(
            f"point not in front of the camera centred at {camera.centre_mm} mm "
            f"(smallest depth {np.nanmin(depth):.6g} mm)"
        )
    x = rel[..., 0] / depth
    y = rel[..., 1] / depth
    return np.stack([camera.u0 + camera.a_u * x + camera.skew * y, camera.v0 + camera.a_v * y], -1)


def projection_jacobian(camera: PinholeCamera, camera_p_mm: np.ndarray) -> np.ndarray:
    """d(u, v)/d(x, y, z) of :func:`project_pinhole` (x, y, z in the camera frame), shape
    (..., 2, 3), px per mm."""
    rel = _in_camera(camera, camera_p_mm)
    x_, y_, z_ = rel[..., 0], rel[..., 1], rel[..., 2]
    jac = np.zeros(rel.shape[:-1] + (2, 3))
    jac[..., 0, 0] = camera.a_u / z_
    jac[..., 0, 1] = camera.skew / z_
    jac[..., 0, 2] = -(camera.a_u * x_ + camera.skew * y_) / z_**2
    jac[..., 1, 1] = camera.a_v / z_
    jac[..., 1, 2] = -camera.a_v * y_ / z_**2
    if camera.is_parallel:
        return jac
    return jac @ camera.rotation.T  # d(R^T P)/dP = R^T


def project(
    params: PsvsParams, camera_p_mm: np.ndarray, distort: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Forward PSVS model, the exact inverse of eq. (4): points (..., 3) in the camera frame
    (mm) -> ``(uv_right_px, uv_left_px)``, each (..., 2), in the complex image. With
    ``distort`` (default) the real lens's distortion is applied, giving what the camera
    observes; without it, the ideal pinhole pixels that eq. (4) takes."""
    uv_r = project_pinhole(params.right_camera, camera_p_mm)
    uv_l = project_pinhole(params.left_camera, camera_p_mm)
    if distort and params.has_distortion:
        k = params.real_camera_matrix
        uv_r = distort_pixels(uv_r, k, params.dist_coeffs)
        uv_l = distort_pixels(uv_l, k, params.dist_coeffs)
    return uv_r, uv_l


# --------------------------------------------------------------------------- triangulation


def parallel_pixels(camera: PinholeCamera, uv_px: np.ndarray) -> np.ndarray:
    """Ideal pixels (..., 2) seen by ``camera`` -> the pixels (..., 2) that the parallel
    camera (same centre and intrinsics A, axes of the camera frame) sees for the same
    rays: the homography ``A R A^-1`` (R = ``camera_R_virtual``). The input itself when
    the camera is parallel. This is how every triangulator handles a rotated (mirror
    tilted) virtual camera before eq. (4)/(2)."""
    uv = _pixels(uv_px, "uv_px")
    if camera.is_parallel:
        return uv
    a = camera.matrix
    h = a @ camera.rotation @ np.linalg.inv(a)
    ray = uv @ h[:, :2].T + h[:, 2]  # h @ (u, v, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return ray[..., :2] / ray[..., 2:3]


def _deskewed_offsets(camera: PinholeCamera, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u - u0 - c (v - v0)/a_v, v - v0): the centred pixel coordinates of eq. (2), with the
    skew of eq. (1) removed."""
    dv = uv[..., 1] - camera.v0
    du = uv[..., 0] - camera.u0 - (camera.skew / camera.a_v) * dv
    return du, dv


def _check_disparity(denominator: np.ndarray) -> None:
    if np.any(~np.isfinite(denominator)) or np.any(np.abs(denominator) < 1e-12):
        raise GeometryError(
            "zero disparity between the right and left image points: the point is at "
            "infinity (or the pair is wrong)"
        )


def _check_in_front(camera_p_mm: np.ndarray, *cameras: PinholeCamera) -> None:
    for cam in cameras:
        depth = (
            camera_p_mm[..., 2] - cam.centre_mm[2]
            if cam.is_parallel
            else _in_camera(cam, camera_p_mm)[..., 2]
        )
        if np.any(~(depth > 0)):
            raise GeometryError(
                "triangulated point lies behind a virtual camera (depth "
                f"{np.nanmin(depth):.6g} mm): swapped right/left points or a wrong pair"
            )


def eq4_points_mm(params: PsvsParams, uv_right_px: np.ndarray, uv_left_px: np.ndarray) -> np.ndarray:
    """Eq. (4), as printed, without checks: ideal (undistorted) pixels of right and left
    views (..., 2) -> points (..., 3) in the camera frame, mm; a pair with no disparity
    gives inf/NaN, a wrong pair a point behind the cameras (for scoring many candidate
    pairs, whose gates drop those). :func:`triangulate_eq4` checks.

    ``z = (a_u (b + m) + l (u_L - u0L)) / ((u_L - u0L) - (u_R - u0R)) - b/2``;
    ``x = (z + b/2)(u_R - u0R)/a_u + b/2`` (the left-view x equation gives the same value
    algebraically; their mean is returned); ``y`` is the mean of the right-view
    ``(z + b/2)(v_R - v0R)/a_v`` and the left-view ``(z + b/2 - l)(v_L - v0L)/a_v``.
    Eq. (4) has no skew; a non-zero skew c is removed first (``u - c (v - v0)/a_v``).
    Rotated virtual cameras: their pixels are first mapped into the parallel cameras
    (:func:`parallel_pixels`).
    """
    return _eq4(params, _pixels(uv_right_px, "uv_right_px"), _pixels(uv_left_px, "uv_left_px"))[0]


def _eq4(params: PsvsParams, uv_r: np.ndarray, uv_l: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(points (..., 3), disparity denominator (...,)) of :func:`eq4_points_mm`."""
    a_u, a_v, b, m, l = params.a_u, params.a_v, params.baseline_mm, params.m_mm, params.l_mm
    uv_r = parallel_pixels(params.right_camera, uv_r)
    uv_l = parallel_pixels(params.left_camera, uv_l)
    du_r, dv_r = _deskewed_offsets(params.right_camera, uv_r)
    du_l, dv_l = _deskewed_offsets(params.left_camera, uv_l)
    denominator = du_l - du_r
    p = np.empty(denominator.shape + (3,))
    with np.errstate(divide="ignore", invalid="ignore"):
        # z + b/2 and z + b/2 - l: the depths in front of the right and left virtual cameras
        depth_r = (a_u * (b + m) + l * du_l) / denominator
        depth_l = depth_r - l
        # means of the right and left x equations, (depth_r du_R/a_u + b/2) and
        # (depth_l du_L/a_u - b/2 - m), and of the two y equations
        p[..., 0] = (depth_r * du_r + depth_l * du_l) * (0.5 / a_u) - 0.5 * m
        p[..., 1] = (depth_r * dv_r + depth_l * dv_l) * (0.5 / a_v)
    p[..., 2] = depth_r - b / 2.0
    return p, denominator


def triangulate_eq4(
    params: PsvsParams, uv_right_px: np.ndarray, uv_left_px: np.ndarray
) -> np.ndarray:
    """Eq. (4) (:func:`eq4_points_mm`) of one point's ideal pixels in the right and left
    views (..., 2) -> the point (..., 3) in the camera frame, mm. Raises
    :class:`GeometryError` for a zero disparity and for a point behind a virtual camera."""
    p, denominator = _eq4(params, _pixels(uv_right_px, "uv_right_px"), _pixels(uv_left_px, "uv_left_px"))
    _check_disparity(denominator)
    _check_in_front(p, params.right_camera, params.left_camera)
    return p


def triangulate_eq2(
    right: PinholeCamera, left: PinholeCamera, uv_right_px: np.ndarray, uv_left_px: np.ndarray
) -> np.ndarray:
    """Eq. (2): the general formula for two parallel cameras with optical centres
    (x0R, y0R, z0R), (x0L, y0L, z0L) and their own a_u, a_v, u0, v0 - an ordinary stereo rig
    or, with eq. (3), the PSVS (then it equals eq. (4)). Ideal pixels (..., 2) -> point
    (..., 3) in mm. ``z`` from the u coordinates; ``x`` and ``y`` are the means of the
    right- and left-view equations. Skew is removed first, as in :func:`triangulate_eq4`.
    The cameras must be displaced along x (a horizontal baseline); rotated cameras are
    first mapped into parallel ones (:func:`parallel_pixels`)."""
    uv_r = parallel_pixels(right, _pixels(uv_right_px, "uv_right_px"))
    uv_l = parallel_pixels(left, _pixels(uv_left_px, "uv_left_px"))
    du_r, dv_r = _deskewed_offsets(right, uv_r)
    du_l, dv_l = _deskewed_offsets(left, uv_l)
    (x0r, y0r, z0r), (x0l, y0l, z0l) = right.centre_mm, left.centre_mm
    denominator = left.a_u * du_r - right.a_u * du_l
    _check_disparity(denominator)
    z = (
        left.a_u * du_r * z0r - right.a_u * du_l * z0l + left.a_u * right.a_u * (x0l - x0r)
    ) / denominator
    x_right = du_r / right.a_u * (z - z0r) + x0r
    x_left = du_l / left.a_u * (z - z0l) + x0l
    y_right = dv_r / right.a_v * (z - z0r) + y0r
    y_left = dv_l / left.a_v * (z - z0l) + y0l
    p = np.stack([0.5 * (x_right + x_left), 0.5 * (y_right + y_left), z], axis=-1)
    _check_in_front(p, right, left)
    return p


def triangulate_lsq(
    right: PinholeCamera,
    left: PinholeCamera,
    uv_right_px: np.ndarray,
    uv_left_px: np.ndarray,
    refine: bool = True,
    max_iter: int = 20,
) -> np.ndarray:
    """Least-squares triangulation from all four image coordinates (eq. (2) as an
    over-determined linear system, then Gauss-Newton on the reprojection error).

    The four lines of eq. (2), ``x - x_n,k (z - z0k) = x0k`` and ``y - y_n,k (z - z0k) = y0k``
    for k = R, L with ``x_n = (u - u0)/a_u``, ``y_n = (v - v0)/a_v``, are solved for (x, y, z)
    in the least-squares sense, each row weighted by ``a/(z - z0k)`` so that its residual is
    in pixels. With ``refine`` (default), Gauss-Newton then minimises the sum of squared
    pixel reprojection errors - the maximum-likelihood point for i.i.d. pixel noise. Ideal
    pixels (..., 2) -> point (..., 3) in mm. Rotated cameras: the linear steps use the
    pixels mapped into the parallel cameras (:func:`parallel_pixels`), Gauss-Newton the
    observed pixels with the rotated projection.
    """
    uv_r = _pixels(uv_right_px, "uv_right_px")
    uv_l = _pixels(uv_left_px, "uv_left_px")
    batch = np.broadcast_shapes(uv_r.shape[:-1], uv_l.shape[:-1])
    uv = {0: np.broadcast_to(uv_r, batch + (2,)), 1: np.broadcast_to(uv_l, batch + (2,))}
    cams = (right, left)
    # Initial guess from eq. (2) itself, then one re-weighted linear solve.
    p = triangulate_eq2(right, left, uv[0], uv[1])
    rows, rhs = [], []
    for k, cam in enumerate(cams):
        du, dv = _deskewed_offsets(cam, parallel_pixels(cam, uv[k]))
        xn, yn = du / cam.a_u, dv / cam.a_v
        depth = p[..., 2] - cam.centre[2]
        wu, wv = cam.a_u / depth, cam.a_v / depth
        zeros = np.zeros_like(xn)
        ones = np.ones_like(xn)
        rows.append(np.stack([wu * ones, zeros, -wu * xn], -1))
        rhs.append(wu * (cam.centre[0] - xn * cam.centre[2]))
        rows.append(np.stack([zeros, wv * ones, -wv * yn], -1))
        rhs.append(wv * (cam.centre[1] - yn * cam.centre[2]))
    a_mat = np.stack(rows, -2)  # (..., 4, 3)
    b_vec = np.stack(rhs, -1)  # (..., 4)
    ata = np.swapaxes(a_mat, -1, -2) @ a_mat
    atb = np.einsum("...ji,...j->...i", a_mat, b_vec)
    p = np.linalg.solve(ata, atb[..., None])[..., 0]
    if refine:
        observed = np.concatenate([uv[0], uv[1]], axis=-1)  # (..., 4)
        for _ in range(max_iter):
            _check_in_front(p, right, left)
            predicted = np.concatenate([project_pinhole(c, p) for c in cams], axis=-1)
            jac = np.concatenate([projection_jacobian(c, p) for c in cams], axis=-2)  # (...,4,3)
            resid = observed - predicted
            jtj = np.swapaxes(jac, -1, -2) @ jac
            jtr = np.einsum("...ji,...j->...i", jac, resid)
            step = np.linalg.solve(jtj, jtr[..., None])[..., 0]
            p = p + step
            if np.all(np.abs(step) <= 1e-13 * np.maximum(1.0, np.abs(p))):
                break
    _check_in_front(p, right, left)
    return p


def triangulate(
    params: PsvsParams,
    uv_right_px: np.ndarray,
    uv_left_px: np.ndarray,
    method: str = "eq4",
    undistort: bool = True,
) -> np.ndarray:
    """The whole chain: observed complex-image pixels of the right and left views (..., 2)
    -> point (..., 3) in the camera frame (mm). With ``undistort`` (default) the lens
    distortion is removed first; ``method`` is ``"eq4"`` (the paper), ``"eq2"`` (general
    parallel pair, equal to eq. (4) for a PSVS) or ``"lsq"`` (all four coordinates,
    reprojection-error optimal). :func:`project` followed by this returns the point."""
    if method not in TRIANGULATION_METHODS:
        raise ValueError(f"method must be one of {TRIANGULATION_METHODS}, got {method!r}")
    uv_r = _pixels(uv_right_px, "uv_right_px")
    uv_l = _pixels(uv_left_px, "uv_left_px")
    if undistort and params.has_distortion:
        k = params.real_camera_matrix
        uv_r = undistort_pixels(uv_r, k, params.dist_coeffs)
        uv_l = undistort_pixels(uv_l, k, params.dist_coeffs)
    if method == "eq4":
        return triangulate_eq4(params, uv_r, uv_l)
    if method == "eq2":
        return triangulate_eq2(params.right_camera, params.left_camera, uv_r, uv_l)
    return triangulate_lsq(params.right_camera, params.left_camera, uv_r, uv_l)
