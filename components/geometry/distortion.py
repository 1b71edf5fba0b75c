"""Lens distortion of the real camera: OpenCV's radial/tangential model in numpy.

The paper calibrates the camera with Zhang's method (Section 2, appendix), which yields
the intrinsic matrix of eq. (1) and distortion coefficients. In a PSVS both virtual views
pass through the one real lens, so one set of coefficients, applied around the real
camera's intrinsics, distorts the whole complex image.

Model (OpenCV ``k1, k2, p1, p2, k3``), on normalised coordinates ``(x, y)`` of the real
camera, ``r^2 = x^2 + y^2``::

    radial = 1 + k1 r^2 + k2 r^4 + k3 r^6
    x_d = x radial + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y radial + p1 (r^2 + 2 y^2) + 2 p2 x y

Pixels relate to normalised coordinates by eq. (1): ``u = u0 + a_u x + c y``,
``v = v0 + a_v y``. Removal solves the model with Newton's method (analytic 2x2 Jacobian)
to ~1e-15 in normalised units, i.e. far below 1e-9 px.
"""

from __future__ import annotations

import numpy as np

from .errors import GeometryError

__all__ = [
    "normalise_pixels",
    "pixels_from_normalised",
    "distort_normalised",
    "undistort_normalised",
    "distort_pixels",
    "undistort_pixels",
    "as_dist_coeffs",
]


def as_dist_coeffs(dist_coeffs) -> np.ndarray:
    """Return ``(k1, k2, p1, p2, k3)`` as a float array from 4 or 5 OpenCV coefficients
    (``None`` means no distortion)."""
    if dist_coeffs is None:
        return np.zeros(5)
    d = np.asarray(dist_coeffs, dtype=float).ravel()
    if d.size == 4:
        d = np.append(d, 0.0)
    if d.size != 5:
        raise ValueError(
            f"distortion coefficients must be (k1, k2, p1, p2[, k3]), got {d.size} values"
        )
    if not np.all(np.isfinite(d)):
        raise ValueError("distortion coefficients must be finite")
    return d


def normalise_pixels(uv_px: np.ndarray, camera_matrix: np.ndarray) -> np.ndarray:
    """Eq. (1) inverted: pixels (..., 2) -> normalised image coordinates (..., 2) for the
    intrinsic matrix ``[[a_u, c, u0], [0, a_v, v0], [0, 0, 1]]`` (skew ``c`` included)."""
    uv_px = np.asarray(uv_px, dtype=float)
    k = np.asarray(camera_matrix, dtype=float)
    y = (uv_px[..., 1] - k[1, 2]) / k[1, 1]
    x = (uv_px[..., 0] - k[0, 2] - k[0, 1] * y) / k[0, 0]
    return np.stack([x, y], axis=-1)


def pixels_from_normalised(xy: np.ndarray, camera_matrix: np.ndarray) -> np.ndarray:
    """Eq. (1): normalised coordinates (..., 2) -> pixels (..., 2), with skew."""
    xy = np.asarray(xy, dtype=float)
    k = np.asarray(camera_matrix, dtype=float)
    u = k[0, 0] * xy[..., 0] + k[0, 1] * xy[..., 1] + k[0, 2]
    v = k[1, 1] * xy[..., 1] + k[1, 2]
    return np.stack([u, v], axis=-1)


def _distort_with_jacobian(xy: np.ndarray, d: np.ndarray):
    k1, k2, p1, p2, k3 = d
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    g = 2.0 * k1 + r2 * (4.0 * k2 + 6.0 * k3 * r2)  # d(radial)/d(r^2) * 2
    j00 = radial + g * x * x + 2.0 * p1 * y + 6.0 * p2 * x
    j01 = g * x * y + 2.0 * p1 * x + 2.0 * p2 * y
    j10 = g * x * y + 2.0 * p1 * x + 2.0 * p2 * y
    j11 = radial + g * y * y + 6.0 * p1 * y + 2.0 * p2 * x
    return np.stack([xd, yd], axis=-1), (j00, j01, j10, j11)


def distort_normalised(xy: np.ndarray, dist_coeffs) -> np.ndarray:
    """Apply OpenCV's radial/tangential distortion to normalised coordinates (..., 2)."""
    xy = np.asarray(xy, dtype=float)
    out, _ = _distort_with_jacobian(xy, as_dist_coeffs(dist_coeffs))
    return out


def undistort_normalised(
    xy_distorted: np.ndarray, dist_coeffs, max_iter: int = 50, tol: float = 1e-15
) -> np.ndarray:
    """Remove the distortion: solve ``distort_normalised(xy) = xy_distorted`` (..., 2) by
    Newton's method. Raises :class:`GeometryError` if it does not converge (a point beyond
    the region where the polynomial model is invertible)."""
    target = np.asarray(xy_distorted, dtype=float)
    d = as_dist_coeffs(dist_coeffs)
    if not np.any(d):
        return target.copy()
    xy = target.copy()
    for _ in range(max_iter):
        f, (j00, j01, j10, j11) = _distort_with_jacobian(xy, d)
        r = f - target
        det = j00 * j11 - j01 * j10
        with np.errstate(divide="ignore", invalid="ignore"):
            dx = (j11 * r[..., 0] - j01 * r[..., 1]) / det
            dy = (-j10 * r[..., 0] + j00 * r[..., 1]) / det
        step = np.stack([dx, dy], axis=-1)
        xy = xy - step
        if np.all(np.abs(step) <= tol * np.maximum(1.0, np.abs(xy))):
            break
    f, (j00, j01, j10, j11) = _distort_with_jacobian(xy, d)
    residual = np.abs(f - target)
    r2 = np.sum(xy * xy, axis=-1)
    radial = 1.0 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]))
    folded = (radial <= 0) | (j00 * j11 - j01 * j10 <= 0)
    if np.any(folded & np.isfinite(r2)):
        raise GeometryError(
            "undistortion found only a folded-over solution: the point lies beyond the "
            "region where the distortion model is invertible"
        )
    if not np.all(np.isfinite(xy)) or np.any(residual > 1e-12):
        worst = np.nanmax(residual) if np.any(np.isfinite(residual)) else float("nan")
        raise GeometryError(
            "undistortion did not converge (residual "
            f"{worst:.3g} in normalised units): the point lies where the distortion "
            "model is not invertible"
        )
    return xy


def distort_pixels(uv_ideal_px: np.ndarray, camera_matrix: np.ndarray, dist_coeffs) -> np.ndarray:
    """Ideal (pinhole) pixels (..., 2) -> observed (distorted) pixels, around
    ``camera_matrix`` (eq. (1), with skew). Equals ``cv2.projectPoints`` for c = 0."""
    if not np.any(as_dist_coeffs(dist_coeffs)):
        return np.array(uv_ideal_px, dtype=float)
    xy = normalise_pixels(uv_ideal_px, camera_matrix)
    return pixels_from_normalised(distort_normalised(xy, dist_coeffs), camera_matrix)


def undistort_pixels(
    uv_observed_px: np.ndarray, camera_matrix: np.ndarray, dist_coeffs
) -> np.ndarray:
    """Observed pixels (..., 2) -> ideal pixels; equals
    ``cv2.undistortPoints(..., P=camera_matrix)`` iterated to convergence."""
    if not np.any(as_dist_coeffs(dist_coeffs)):
        return np.array(uv_observed_px, dtype=float)
    xy = normalise_pixels(uv_observed_px, camera_matrix)
    return pixels_from_normalised(undistort_normalised(xy, dist_coeffs), camera_matrix)
